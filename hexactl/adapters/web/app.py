"""``hexactl dashboard``: the web page, its WebSocket and the recordings' downloads.

Starlette (routing, static files, WebSockets) served by uvicorn: a maintained ASGI stack
whose WebSocket endpoint and the ZeroMQ client threads meet on one asyncio loop without
any glue of ours (docs/dashboard.md says why this one).

The page and the vendored libraries (three.js, uPlot) come from the package: nothing
from the internet. Commands arrive on the WebSocket as ``{"type": "command", "id": N,
"cmd": NAME, …fields}`` and go to the API unchanged; the reply comes back as
``{"type": "reply", "id": N, "reply": …}``. The page is sent ``{"type": "hello",
"command_timeout_ms": …}`` first: how long it waits for a reply, the time to live the
dashboard gives each of its commands from when the page sent it (:class:`PageClock`,
:mod:`.bridge`). The page acknowledges the telemetry it has
handled (``{"type": "ack", "n": N}``), and is sent no more than a window ahead of it; each
acknowledgement read is answered ``{"type": "acked", "n": N, "server_ms": …}`` behind what
the page was sent before, which times how far behind the page is, and how far its clock is
off this host's.

Loopback only, a request whose ``Host`` or WebSocket ``Origin`` is not this server's is
refused, and no response may be shown in another page's frame: another web site open in
the operator's browser cannot drive the platform through it (DNS rebinding, cross-site
WebSockets, clickjacking). With a ``token`` (the dashboard reaches the service with CURVE
keys), the page, its WebSocket and the downloads need it too: another account or process
on this host, without the keys, gets no more through the dashboard than from the service.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import re
import secrets
import time
from collections import deque
from collections.abc import AsyncIterator
from dataclasses import dataclass
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from starlette.applications import Starlette
from starlette.requests import HTTPConnection, Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, Response, StreamingResponse
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from hexactl.adapters.api.protocol import RECORDING_NAME_PATTERN
from hexactl.adapters.web.bridge import URGENT_COMMANDS, ServiceBridge, error_reply, finite_number

MAX_MESSAGE_BYTES = 64 * 1024
"""The largest WebSocket message a page may send (a command is a few hundred bytes)."""

MAX_COMMANDS_IN_FLIGHT = 16
"""Commands one page may have waiting for replies; beyond, it is answered ``busy``."""

MAX_READ_AHEAD = 64
"""Commands one page may have waiting, ``estop``, ``stop`` and ``abort`` included (never
answered ``busy``), before its next message is read only once one is answered."""

DOWNLOAD_CHUNK_BYTES = 1024 * 1024

PAGE_CLOCK_SAMPLES = 256
"""The page's latest messages whose least delay is taken for none (:class:`PageClock`): half
a minute at least of its acknowledgements while records come (it sends one every 250 ms
and every 8th record)."""

log = logging.getLogger("hexactl.dashboard")


def static_directory() -> str:
    return str(resources.files("hexactl.adapters.web") / "static")


def create_app(bridge: ServiceBridge, allowed_hosts: frozenset[str], token: str | None = None) -> Starlette:
    """The dashboard's ASGI application over ``bridge``; ``allowed_hosts``: the ``host:port``
    forms a request's ``Host`` (and a WebSocket's ``Origin``) may name (the port left out
    where it is the scheme's default: :func:`host_allowed`); ``token``: the secret the page,
    its WebSocket and the downloads must carry (:func:`token_given`; None: none needed)."""

    def unauthorised(connection: HTTPConnection) -> bool:
        return token is not None and not secrets.compare_digest(token_given(connection).encode(), token.encode())

    def refused() -> Response:
        return PlainTextResponse("this dashboard needs its token: open the URL it printed at its start "
                                 "(http://HOST:PORT/?token=…)", status_code=403)

    async def index(request: Request) -> Response:
        if unauthorised(request):
            return refused()
        return FileResponse(f"{static_directory()}/index.html", headers={"Cache-Control": "no-store"})

    async def download(request: Request) -> Response:
        if unauthorised(request):
            return refused()
        name = request.path_params["name"]
        if not (name.endswith(".csv") and re.fullmatch(RECORDING_NAME_PATTERN, name.removesuffix(".csv"))):
            return PlainTextResponse(f"{name}: not a recording's name (NAME.csv, as given to record)", status_code=400)
        first = await bridge.command("read_file", {"path": name, "offset": 0, "length": DOWNLOAD_CHUNK_BYTES})
        if not first.get("ok"):
            error = first.get("error") or {}
            status = 404 if error.get("code") in ("file_not_found", "forbidden_path") else 502
            return PlainTextResponse(f"{name}: {error.get('message', 'no answer')}", status_code=status)
        return StreamingResponse(_chunks(bridge, name, first), media_type="text/csv",
                                 headers={"Content-Disposition": f'attachment; filename="{name}"'})

    async def health(request: Request) -> Response:
        return JSONResponse({"connected": bridge.connected, "api": bridge.endpoints.api,
                             "telemetry": bridge.endpoints.telemetry})

    async def socket(websocket: WebSocket) -> None:
        origin = websocket.headers.get("origin")
        if origin is not None and not origin_allowed(origin, allowed_hosts):
            log.warning("refused a WebSocket from origin %s (not this dashboard's page)", origin)
            await websocket.close(code=1008)
            return
        if unauthorised(websocket):
            log.warning("refused a WebSocket without this dashboard's token")
            await websocket.close(code=1008)
            return
        await websocket.accept()
        await _serve_page(bridge, websocket, bridge.hello())

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        bridge.start(asyncio.get_running_loop())
        try:
            yield
        finally:
            bridge.close()

    app = Starlette(routes=[
        Route("/", index),
        Route("/health", health),
        Route("/recordings/{name}", download),
        WebSocketRoute("/ws", socket),
        Mount("/static", StaticFiles(directory=static_directory()), name="static"),
    ], lifespan=lifespan)
    return _NotFramed(_HostCheck(app, allowed_hosts))


def token_given(connection: HTTPConnection) -> str:
    """The token a request carries ("" if none): its URL's ``token`` (the page's, opened
    from the URL printed, and its WebSocket's), else its ``Referer``'s (a download link the
    page followed: a same-origin request's Referer is the page's whole URL)."""
    for query in (connection.url.query, urlsplit(connection.headers.get("referer", "")).query):
        if tokens := parse_qs(query).get("token"):
            return tokens[0]
    return ""


NOT_FRAMED_HEADERS = ((b"x-frame-options", b"DENY"), (b"content-security-policy", b"frame-ancestors 'none'"),
                      (b"x-content-type-options", b"nosniff"))


class _NotFramed:
    """Every HTTP response forbids its showing in a frame: another site open in the
    operator's browser could show the page, live, in its own under a decoy and have the
    operator's clicks press its buttons (clickjacking: the framed page's Host and Origin
    are the dashboard's own). And no content sniffing: each response is what its type says."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_not_framed(message: dict[str, Any]) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", ()), *NOT_FRAMED_HEADERS]}
            await send(message)

        await self.app(scope, receive, send_not_framed)


DEFAULT_PORTS = {"http": 80, "ws": 80, "https": 443, "wss": 443}
"""The port a browser leaves out of ``Host`` and ``Origin`` for each scheme."""

_WITHOUT_PORT = re.compile(r"\[[^\]]*\]|[^:\[\]]+")


def _with_port(authority: str, scheme: str) -> str:
    """``authority`` (``host[:port]``) as ``host:port``: a browser names no port when it is
    the scheme's default (``http://127.0.0.1/`` sends ``Host: 127.0.0.1``)."""
    if _WITHOUT_PORT.fullmatch(authority) and (port := DEFAULT_PORTS.get(scheme.lower())) is not None:
        return f"{authority}:{port}"
    return authority


def host_allowed(host: str, scheme: str, allowed_hosts: frozenset[str]) -> bool:
    """Whether a request's ``Host`` (of a request in ``scheme``: http, ws…) names this
    server: one of ``allowed_hosts`` (``host:port``), or its host alone where the port is
    the scheme's default."""
    return _with_port(host, scheme) in allowed_hosts


def origin_allowed(origin: str, allowed_hosts: frozenset[str]) -> bool:
    """Whether a WebSocket's ``Origin`` is a page of this server: http or https, on one of
    ``allowed_hosts`` (its port left out only where it is the scheme's default)."""
    scheme, separator, host = origin.partition("://")
    return bool(separator) and scheme in ("http", "https") and host_allowed(host, scheme, allowed_hosts)


class _HostCheck:
    """Refuse an HTTP request or WebSocket whose ``Host`` is not this server's (a page
    that reached us by DNS rebinding names its own host)."""

    def __init__(self, app: Any, allowed_hosts: frozenset[str]) -> None:
        self.app = app
        self.allowed_hosts = allowed_hosts

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] in ("http", "websocket"):
            host = dict(scope["headers"]).get(b"host", b"").decode("latin-1")
            if not host_allowed(host, scope.get("scheme", "http"), self.allowed_hosts):
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": 1008})
                    return
                response = PlainTextResponse(f"Host {host!r} is not this dashboard's", status_code=421)
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)


async def _serve_page(bridge: ServiceBridge, websocket: WebSocket, hello: str | None = None) -> None:
    """One page: ``hello`` first (:meth:`ServiceBridge.hello`), then updates out, commands
    in, until it goes.

    The updates have a task of this page's own, and replies go out from each command's
    task: a page that does not read blocks only its own sends (its outbox keeps the newest
    update of each kind meanwhile), never another page's, nor the receipt of its own
    commands."""
    updates = bridge.subscribe()
    clock = PageClock()
    in_flight: set[asyncio.Task[None]] = set()
    browser = websocket.client.host if websocket.client else None  # the service's events name it

    async def send(text: str) -> None:
        # A page gone is sent nothing: the commands it sent are carried out all the same,
        # and their replies must not end their tasks failed (a traceback each in the log).
        if websocket.application_state is WebSocketState.DISCONNECTED:  # a send to it failed already
            return
        with contextlib.suppress(WebSocketDisconnect):
            await websocket.send_text(text)

    async def send_updates() -> None:
        while True:
            await send(await updates.get())

    async def reply(request_id: Any, reply: dict[str, Any]) -> None:
        await send(json.dumps({"type": "reply", "id": request_id, "reply": reply}))

    async def answer(request_id: Any, received: float, cmd: str, fields: dict[str, Any]) -> None:
        try:
            outcome = await bridge.command(cmd, fields, browser, received)
        except Exception as error:  # every command gets a reply, whatever fails on the way
            log.exception("command %s from a page failed", cmd)
            outcome = error_reply("internal_error", f"the dashboard could not carry {cmd}: {type(error).__name__}: {error}")
        await reply(request_id, outcome)

    if hello is not None:
        await send(hello)  # before anything else: the page's timeout for its commands
    sender = asyncio.create_task(send_updates())
    try:
        while True:
            received = await websocket.receive()
            received_at = time.monotonic()
            if received["type"] == "websocket.disconnect":
                break
            if received.get("text") is None:
                await reply(None, error_reply("invalid_request", "the page sends text messages (JSON), not binary"))
                continue
            request_id, parsed = _parsed(received["text"])
            if isinstance(parsed, str):
                await reply(request_id, error_reply("invalid_request", parsed))
                continue
            at = parsed.at if isinstance(parsed, Acknowledgement) else parsed[1].pop("at", None)
            if at is not None:  # a sample of the page's clock; a command's time to live counts from when it was sent
                received_at -= clock.transit_s(at, received_at)
            if isinstance(parsed, Acknowledgement):
                updates.acknowledge(parsed.number)
                continue
            if len(in_flight) >= MAX_COMMANDS_IN_FLIGHT and parsed[0] not in URGENT_COMMANDS:
                await reply(request_id, error_reply(
                    "busy", f"{MAX_COMMANDS_IN_FLIGHT} commands of this page are waiting: wait for their replies"))
                continue
            task = asyncio.create_task(answer(request_id, received_at, *parsed))
            in_flight.add(task)
            task.add_done_callback(in_flight.discard)
            if len(in_flight) >= MAX_READ_AHEAD:
                # Flooding estop, stop or abort: a task each would pile up without end. The
                # page is read on once one is answered (its presses not yet read are
                # carried out no later: each waits for the request being sent to end).
                await asyncio.wait(in_flight, return_when=asyncio.FIRST_COMPLETED)
    except WebSocketDisconnect:
        pass
    finally:
        sender.cancel()
        bridge.unsubscribe(updates)


def _not_json(constant: str) -> Any:
    raise ValueError(f"{constant} is not a JSON number: commands take finite numbers")


@dataclass(frozen=True, slots=True)
class Acknowledgement:
    """The page has handled the telemetry message ``number`` (its ``n``) and those before it;
    ``at``: when it said so, ms on its clock (its ``performance.now()``; None: not given)."""

    number: int
    at: float | None = None


def _parsed(text: str) -> tuple[Any, tuple[str, dict[str, Any]] | Acknowledgement | str]:
    """(the message's id, (cmd, fields), an acknowledgement, or why it is neither). A
    command's ``at``, checked, stays among its fields; the caller takes it out."""
    if len(text) > MAX_MESSAGE_BYTES:
        return None, f"a message is at most {MAX_MESSAGE_BYTES} bytes"
    try:
        message = json.loads(text, parse_constant=_not_json)
    except (ValueError, RecursionError) as error:  # JSONDecodeError, NaN, a number of thousands of digits, deep nesting
        return None, f"not JSON: {error}"
    if not isinstance(message, dict):
        return None, "a message is a JSON object"
    request_id = message.get("id")
    at = message.get("at")
    if at is not None and not (finite_number(at) and at >= 0):
        return request_id, f"at is the page's performance.now() when it sent the message, ms ≥ 0, got {at!r:.40}"
    if message.get("type") == "ack":
        number = message.get("n")
        if type(number) is not int or number < 0:  # noqa: E721 - a bool is no message number
            return request_id, "an ack is {\"type\": \"ack\", \"n\": N}: N the n of the last telemetry message handled"
        return request_id, Acknowledgement(number, at)
    if message.get("type") != "command":
        return request_id, ("the page sends {\"type\": \"command\", \"id\": N, \"cmd\": NAME, …} and "
                            "{\"type\": \"ack\", \"n\": N}, nothing else")
    cmd = message.get("cmd")
    if not isinstance(cmd, str):
        return request_id, "a command names its cmd"
    fields = {key: value for key, value in message.items() if key not in ("type", "id", "cmd")}
    return request_id, (cmd, fields)


class PageClock:
    """How long a page's messages were on their way before the dashboard read them, from
    the ``at`` each carries: the page's ``performance.now()`` when it sent it, ms, on a
    clock of its own (another host's, through a tunnel). A message read at ``read`` (this
    host's monotonic clock) gives ``read − at``: the offset between the clocks plus its
    delay. The least of the page's last :data:`PAGE_CLOCK_SAMPLES` is that of the least
    delayed, taken for none. A window of messages, not of time: a stall of the dashboard,
    however long, delays every message sent during it, and those before it stay in the
    window to measure them by; yet it follows a slow drift between the clocks."""

    def __init__(self) -> None:
        self._offsets_ms: deque[float] = deque(maxlen=PAGE_CLOCK_SAMPLES)

    def transit_s(self, at_ms: float, read_s: float) -> float:
        """How long the message the page sent at ``at_ms`` was on its way (s, ≥ 0; 0 for
        the least delayed) before it was read at ``read_s`` (``time.monotonic()``); a sample
        for the next ones."""
        offset_ms = read_s * 1000.0 - at_ms
        self._offsets_ms.append(offset_ms)
        return (offset_ms - min(self._offsets_ms)) / 1000.0


async def _chunks(bridge: ServiceBridge, name: str, first: dict[str, Any]) -> AsyncIterator[bytes]:
    reply = first
    while True:
        data = base64.b64decode(reply["data_b64"])
        yield data
        if reply["eof"] or not data:
            return
        offset = reply["offset"] + len(data)
        reply = await bridge.command("read_file", {"path": name, "offset": offset, "length": DOWNLOAD_CHUNK_BYTES})
        if not reply.get("ok"):
            log.warning("download of %s broke off: %s", name, (reply.get("error") or {}).get("message"))
            return
