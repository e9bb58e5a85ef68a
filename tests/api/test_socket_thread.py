"""The lifecycle the command server and the telemetry publisher share
(:class:`~hexactl.adapters.api.socket_thread.SocketThread`): bound when made, a busy
endpoint refused with nothing left open, one thread from ``start`` to ``close``, and
``close`` safe before ``start`` and twice."""

from __future__ import annotations

import json
import logging
import socket
import threading
from collections.abc import Callable

import pytest
import zmq

from hexactl.adapters.api.server import MAX_UNREAD_REPLIES, ApiServer
from hexactl.adapters.api.socket_thread import SocketThread
from hexactl.adapters.api.telemetry import TelemetryPublisher
from tests.api.support import LOCAL
from tools.serving import wait_until

WAIT_S = 30.0  # only turns a hang into a failure

MAKERS: dict[str, Callable[[zmq.Context, str], SocketThread]] = {
    "api": lambda context, endpoint: ApiServer(context, endpoint, lambda request, deadline_ns, sender: {"message": "hello"}),
    "telemetry": lambda context, endpoint: TelemetryPublisher(context, endpoint, lambda: {"t": 0.0}),
}


def terminated(context: zmq.Context) -> bool:
    """Whether ``context`` terminates, which it does only once all its sockets are closed."""
    terminating = threading.Thread(target=context.term, daemon=True)
    terminating.start()
    terminating.join(WAIT_S)
    return not terminating.is_alive()


@pytest.mark.parametrize("make", MAKERS.values(), ids=MAKERS)
def test_one_thread_from_start_to_close_then_the_socket_is_closed(make) -> None:
    context = zmq.Context()
    served = make(context, LOCAL)
    assert served.endpoint.startswith("tcp://127.0.0.1:") and not served.endpoint.endswith(":*")
    before = set(threading.enumerate())
    served.start()
    threads = set(threading.enumerate()) - before  # the API server's worker besides
    assert threads
    served.close()
    assert not any(thread.is_alive() for thread in threads)
    served.close()  # a second close does nothing
    assert terminated(context)


@pytest.mark.parametrize("make", MAKERS.values(), ids=MAKERS)
def test_a_busy_endpoint_is_refused_with_nothing_left_open(make) -> None:
    context = zmq.Context()
    first = make(context, LOCAL)
    with pytest.raises(zmq.ZMQError):
        make(context, first.endpoint)
    first.close()  # never started
    assert terminated(context)  # the refused one's socket was closed too


def test_the_api_socket_thread_wakes_the_loop_links_heartbeat_while_a_handler_works() -> None:
    """``on_wake`` is the loop link's heartbeat: it comes from the thread that carries out
    ``estop``, idle or not, and not from the worker, which may be busy planning for long."""
    release = threading.Event()

    def handle(request, deadline_ns, sender) -> dict:
        release.wait(WAIT_S)  # the worker is held in a long request
        return {"message": "done"}

    wakes: list[str] = []
    context = zmq.Context()
    server = ApiServer(context, LOCAL, handle, on_wake=lambda: wakes.append(threading.current_thread().name))
    server.start()
    try:
        wait_until(lambda: len(wakes) >= 3, "the idle socket thread's wakes", WAIT_S)
        dealer = context.socket(zmq.DEALER)
        dealer.linger = 0
        dealer.connect(server.endpoint)
        dealer.send(b'{"v": 1, "cmd": "move", "pose": [0, 0, 0, 0, 0, 0], "id": 1}')
        wait_until(lambda: server._workers[0].in_handler is not None, "the worker in its handler", WAIT_S)
        held = len(wakes)
        wait_until(lambda: len(wakes) >= held + 3, "wakes while the worker is held", WAIT_S)
        assert set(wakes) == {"hexactl-api"}
        release.set()
        assert dealer.poll(round(WAIT_S * 1000)) and b"done" in dealer.recv_multipart()[-1]
        dealer.close()
    finally:
        release.set()
        server.close()
    assert terminated(context)


@pytest.mark.parametrize("make", MAKERS.values(), ids=MAKERS)
def test_an_ipc_endpoint_another_process_serves_is_refused_a_stale_one_taken(make, tmp_path) -> None:
    """ZeroMQ binds ipc://PATH by removing whatever is at PATH: a second service on the
    path of a running one took it over silently, and the first's clients, E-stop included,
    reached the second; a file of the operator's there was deleted."""
    path = tmp_path / "api.ipc"
    endpoint = f"ipc://{path}"
    other = zmq.Context()
    serving = other.socket(zmq.REP)
    serving.bind(endpoint)  # as another process's service would: a listening socket
    context = zmq.Context()
    try:
        with pytest.raises(zmq.ZMQError, match=f"{endpoint}: another process serves there"):
            make(context, endpoint)
        with zmq.Context() as client_context, client_context.socket(zmq.REQ) as client:
            client.linger = 0
            client.connect(endpoint)  # still the first one's
            client.send(b"ping")
            assert serving.poll(WAIT_S * 1000) and serving.recv() == b"ping"
    finally:
        serving.close(linger=0)
        other.term()
    kept = tmp_path / "kept.toml"
    kept.write_text("name = 'calibration'\n")
    with pytest.raises(zmq.ZMQError, match=f"ipc://{kept}: .* not a socket"):
        make(context, f"ipc://{kept}")
    assert kept.read_text() == "name = 'calibration'\n"
    stale = tmp_path / "stale.ipc"  # left by a service that was killed: a socket file nothing listens on
    with socket.socket(socket.AF_UNIX) as gone:
        gone.bind(str(stale))
    served = make(context, f"ipc://{stale}")
    served.close()
    assert terminated(context)


def test_a_client_that_never_reads_its_replies_loses_them_past_the_per_client_bound_and_the_log_says_why(
        caplog) -> None:
    """Found from outside: ZeroMQ kept up to 1000 unread replies a client, so one that
    pipelined ``read_file`` and never read held hundreds of MB of the API process's memory.
    It keeps :data:`MAX_UNREAD_REPLIES` (beyond what the sockets buffer); the rest are
    dropped, said once in the log, and other clients are answered as before."""
    reply = {"message": "x" * 128_000}
    context = zmq.Context()
    server = ApiServer(context, LOCAL, lambda request, deadline_ns, sender: reply)
    server.start()
    hoarder = context.socket(zmq.DEALER)
    hoarder.linger = 0
    hoarder.rcvhwm = 1
    hoarder.setsockopt(zmq.RCVBUF, 4096)
    hoarder.connect(server.endpoint)
    sent = 0

    def dropped() -> bool:
        nonlocal sent
        if sent < 600:  # past 128 unread and the sockets' buffers (about 64 of these replies) without the bound
            for _ in range(16):  # within the requests one client may have waiting
                hoarder.send(json.dumps({"v": 1, "id": sent, "cmd": "status"}).encode())
                sent += 1
        return any(f"it has {MAX_UNREAD_REPLIES} replies unread" in record.getMessage() for record in caplog.records)

    try:
        with caplog.at_level(logging.WARNING, logger="hexactl.adapters.api.server"):
            wait_until(dropped, "the log saying the replies were dropped", WAIT_S, poll_s=0.1,
                       seen=lambda: f"{sent} requests sent")
        reader = context.socket(zmq.DEALER)
        reader.linger = 0
        reader.connect(server.endpoint)
        reader.send(b'{"v": 1, "id": "other", "cmd": "status"}')
        assert reader.poll(round(WAIT_S * 1000)) and b'"other"' in reader.recv()
        reader.close()
    finally:
        hoarder.close()
        server.close()
    assert terminated(context)
