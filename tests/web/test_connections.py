"""The dashboard's HTTP connections (:mod:`hexactl.adapters.web.connections`): one that
sends no complete request head in time is closed, and so is the oldest of too many
waiting at once; answered requests and open WebSockets are not. Before, uvicorn kept a
silent or trickling connection open for good, so a local process holding a thousand of
them left the dashboard without descriptors, and a reconnecting page without its E-stop.

uvicorn runs in a thread here with a small app, the real protocol class but shorter
limits; the dashboard runs it with :class:`GuardedH11Protocol`'s own."""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import uvicorn
from starlette.applications import Starlette
from starlette.responses import PlainTextResponse
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect
from websockets.sync.client import connect

from hexactl.adapters.web import server as dashboard_server
from hexactl.adapters.web.connections import GuardedH11Protocol
from tools.browser import dashboard
from tools.serving import HANG_S, free_port, wait_until

SHORT_S = 0.3


class ShortDeadline(GuardedH11Protocol):
    head_timeout_s = SHORT_S


class FewWaiting(GuardedH11Protocol):
    head_timeout_s = 3600.0  # only the bound closes anything
    max_awaiting_head = 3


async def hello(_request) -> PlainTextResponse:  # noqa: ANN001
    return PlainTextResponse("hello")


async def echo(websocket: WebSocket) -> None:
    await websocket.accept()
    with contextlib.suppress(WebSocketDisconnect):
        while True:
            await websocket.send_text(await websocket.receive_text())


@contextmanager
def served(protocol: type[GuardedH11Protocol]) -> Iterator[int]:
    """uvicorn with ``protocol`` on a free loopback port, in a thread; yields the port."""
    app = Starlette(routes=[Route("/", hello), WebSocketRoute("/ws", echo)])
    listener = dashboard_server.bind(dashboard_server.HttpAddress("127.0.0.1", 0))
    server = uvicorn.Server(uvicorn.Config(app, http=protocol, lifespan="off", log_level="warning"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [listener]}, daemon=True)
    thread.start()
    wait_until(lambda: server.started or not thread.is_alive(), "uvicorn to start", HANG_S)
    assert server.started, "uvicorn ended before it started"
    try:
        yield listener.getsockname()[1]
    finally:
        server.should_exit = True
        thread.join(HANG_S)
        listener.close()


def opened(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=HANG_S)


def closed_by_the_server(connection: socket.socket) -> bool:
    """Whether the server has closed ``connection`` (its end read), without waiting."""
    readable, _, _ = select.select([connection], [], [], 0)
    try:
        return bool(readable) and connection.recv(1, socket.MSG_PEEK) == b""
    except ConnectionResetError:
        return True


def test_a_connection_that_sends_nothing_is_closed() -> None:
    with served(ShortDeadline) as port, opened(port) as silent:
        assert silent.recv(1) == b""  # closed; without the deadline, recv times out (HANG_S)


HEAD = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"
PADDED = HEAD + b"X-Padding: a\r\n" * 10_000


def trickled_until_closed(connection: socket.socket, head: bytes) -> None:
    """Send ``head`` a few bytes at a time, each well within the deadline, until the server
    closes ``connection``; fails if it never does."""
    deadline = time.monotonic() + HANG_S  # bounds a hang only
    for start in range(0, len(head), 8):
        assert time.monotonic() < deadline, "the trickling connection was never closed"
        try:
            connection.sendall(head[start:start + 8])
        except (BrokenPipeError, ConnectionResetError):
            return
        if closed_by_the_server(connection):
            return
        time.sleep(SHORT_S / 10)
    pytest.fail("the whole padded head was sent without the connection being closed")


def test_a_trickled_request_head_is_closed_though_bytes_keep_coming() -> None:
    with served(ShortDeadline) as port, opened(port) as trickling:
        trickled_until_closed(trickling, PADDED)


def test_after_a_reply_the_next_head_has_its_deadline_too() -> None:
    """A kept-alive connection answered once, then trickling its next request: uvicorn's own
    keep-alive timer stops at the first byte of it, so only the deadline ends it."""
    with served(ShortDeadline) as port, opened(port) as client:
        client.sendall(HEAD + b"\r\n")
        answer = b""
        while not answer.endswith(b"hello"):
            answer += client.recv(4096)
        trickled_until_closed(client, PADDED)


def test_answered_requests_and_an_open_websocket_are_not_closed() -> None:
    with served(ShortDeadline) as port, connect(f"ws://127.0.0.1:{port}/ws", open_timeout=HANG_S) as page:
        with opened(port) as client:
            client.sendall(HEAD + b"\r\n")
            answer = b""
            while not answer.endswith(b"hello"):
                answer += client.recv(4096)
            assert answer.startswith(b"HTTP/1.1 200")
        with opened(port) as later:  # past its deadline, so past the page's too: the page waits for no head
            assert later.recv(1) == b""
        page.send("E-stop")
        assert page.recv(HANG_S) == "E-stop"


def test_beyond_the_bound_the_oldest_waiting_connection_is_closed() -> None:
    with served(FewWaiting) as port, connect(f"ws://127.0.0.1:{port}/ws", open_timeout=HANG_S) as page:
        connections = [opened(port) for _ in range(3)]
        newest = opened(port)
        try:
            assert connections[0].recv(1) == b""  # the oldest, once the fourth came
            assert not any(closed_by_the_server(connection) for connection in connections[1:] + [newest])
            page.send("still here")
            assert page.recv(HANG_S) == "still here"
        finally:
            for connection in connections + [newest]:
                connection.close()


def test_the_dashboard_closes_a_connection_that_sends_nothing() -> None:
    """``hexactl dashboard`` itself (no service behind it is needed for this)."""
    api, telemetry = (f"tcp://127.0.0.1:{free_port()}" for _ in range(2))
    with dashboard(api, telemetry) as board:
        port = int(board.url.rstrip("/").rpartition(":")[2])
        with opened(port) as silent:
            assert silent.recv(1) == b""  # after GuardedH11Protocol.head_timeout_s; never, before
