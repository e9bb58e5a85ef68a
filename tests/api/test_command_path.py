"""The command path of :class:`~hexactl.adapters.api.server.ApiServer`: nothing a
handler does holds up ``estop``/``stop``/``abort``; those discard queued motion requests
from every client; clients are queued fairly and bounded (``busy``); a request past its
``deadline_ms`` is answered ``expired`` and not carried out; a stuck handler is reported
by the watchdog; and the smaller refusals of the wire format (duplicate keys, unbounded
durations and dwells)."""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
import zmq

from hexactl.adapters.api.client import DEADLINE_MARGIN_MIN_MS, HexactlClient, deadline_ms
from hexactl.adapters.api.messages import Request
from hexactl.adapters.api.protocol import default_client_name
from hexactl.adapters.api.server import MAX_QUEUED_PER_CLIENT, QUERY_COMMANDS, ApiServer
from hexactl.control.planning import MAX_MOTION_S
from hexactl.adapters.files.sequence_file import sequence_from_toml
from hexactl.control.sequences import SequenceError
from tests.api.support import LOCAL, request
from tools.serving import wait_until

WAIT_S = 10.0  # only turns a hang into a failure
POSE = [0, 0, 10, 0, 0, 0]


class BlockingHandler:
    """Records what it carries out (command, id, deadline); requests whose ``id`` starts
    with "block" wait until :attr:`release` is set, :attr:`entered` set meanwhile."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.entered = threading.Event()
        self.done: list[tuple[str, Any, int | None]] = []
        self.senders: list[str | None] = []
        self.lock = threading.Lock()

    def __call__(self, request: Request, deadline_ns: int | None, sender: str | None) -> dict[str, Any]:
        if isinstance(request.id, str) and request.id.startswith("block"):
            self.entered.set()
            assert self.release.wait(WAIT_S * 3), "never released"
        with self.lock:
            self.done.append((request.cmd, request.id, deadline_ns))
            self.senders.append(sender)
        return {"message": f"{request.cmd} done"}

    def sender(self, request_id: Any) -> str | None:
        with self.lock:
            return next(sender for (_, done_id, _), sender in zip(self.done, self.senders) if done_id == request_id)

    def ids(self) -> list[Any]:
        with self.lock:
            return [request_id for _, request_id, _ in self.done]


@pytest.fixture
def handler() -> BlockingHandler:
    return BlockingHandler()


@pytest.fixture
def server(handler: BlockingHandler) -> Iterator[ApiServer]:
    context = zmq.Context()
    served = ApiServer(context, LOCAL, handler)
    served.start()
    yield served
    handler.release.set()
    served.close()
    context.term()


class Client:
    """A DEALER of its own (one ROUTER identity), sending without waiting."""

    def __init__(self, endpoint: str) -> None:
        self.socket = zmq.Context.instance().socket(zmq.DEALER)
        self.socket.linger = 0
        self.socket.connect(endpoint)

    def send(self, request_id: Any, cmd: str, **fields: Any) -> None:
        self.socket.send(json.dumps({"v": 1, "id": request_id, "cmd": cmd, **fields}).encode())

    def receive(self) -> dict[str, Any]:
        assert self.socket.poll(WAIT_S * 1000), "no reply"
        return json.loads(self.socket.recv())

    def replies(self, count: int) -> dict[Any, dict[str, Any]]:
        return {reply["id"]: reply for reply in (self.receive() for _ in range(count))}

    def close(self) -> None:
        self.socket.close()


def named(name: bytes, endpoint: str) -> zmq.Socket:
    """A DEALER whose connection names its client ``name`` (raw bytes, as any client may send)."""
    socket = zmq.Context.instance().socket(zmq.DEALER)
    socket.linger = 0
    socket.setsockopt(zmq.METADATA, b"X-Client:" + name)
    socket.connect(endpoint)
    return socket


@pytest.mark.parametrize("cmd", ["status", "move", "stop"])  # the query worker, the command worker, the socket thread
def test_the_handler_is_told_who_sent_each_request(server: ApiServer, handler: BlockingHandler, cmd: str) -> None:
    fields = {"pose": POSE} if cmd == "move" else {}
    with HexactlClient(server.endpoint, timeout_s=WAIT_S, name="bench-2 operator") as client:
        reply = client.request(cmd, **fields)
    assert reply["ok"], reply
    assert handler.sender(reply["id"]) == "bench-2 operator (127.0.0.1)"


def test_an_unnamed_client_and_a_name_that_is_not_text_are_still_told_apart(server: ApiServer,
                                                                           handler: BlockingHandler) -> None:
    assert request(server.endpoint, {"v": 1, "id": "unnamed", "cmd": "status"})["ok"]
    assert handler.sender("unnamed") == "an unnamed client (127.0.0.1)"
    socket = named(b"\xffevil\x1b[2J" + b"x" * 100, server.endpoint)
    try:
        socket.send(json.dumps({"v": 1, "id": "odd", "cmd": "status"}).encode())
        assert socket.poll(WAIT_S * 1000)
        assert json.loads(socket.recv())["ok"]
    finally:
        socket.close()
    name = handler.sender("odd")
    assert name == "\ufffdevil?[2J" + "x" * 55 + " (127.0.0.1)", name  # printable, cut to 64 characters


def test_a_client_on_this_host_is_named_by_its_process_and_user_over_ipc(tmp_path, handler: BlockingHandler) -> None:
    context = zmq.Context()
    served = ApiServer(context, f"ipc://{tmp_path}/api.ipc", handler)
    served.start()
    try:
        with HexactlClient(served.endpoint, timeout_s=WAIT_S) as client:
            reply = client.request("status")
        assert handler.sender(reply["id"]) == f"{default_client_name()} (pid {os.getpid()}, uid {os.getuid()})"
    finally:
        served.close()
        context.term()


def blocked(server: ApiServer, handler: BlockingHandler) -> Client:
    """A client whose request holds the command worker until ``handler.release``."""
    client = Client(server.endpoint)
    client.send("block", "validate_pose", pose=POSE)
    assert handler.entered.wait(WAIT_S)
    return client


def test_estop_stop_abort_are_answered_while_the_worker_is_stuck(server, handler) -> None:
    holder = blocked(server, handler)
    for cmd in ("estop", "stop", "abort"):
        reply = request(server.endpoint, {"v": 1, "id": cmd, "cmd": cmd})
        assert reply["ok"] and reply["message"] == f"{cmd} done"
    assert not handler.release.is_set() and handler.ids() == ["estop", "stop", "abort"]  # the worker is still held
    handler.release.set()
    assert holder.receive()["id"] == "block"
    holder.close()


def test_queries_are_answered_while_the_command_worker_plans(server, handler) -> None:
    """Found from outside: ``status`` waited behind another client's long plan, and the
    command line said the service was not running."""
    holder = blocked(server, handler)
    for cmd in sorted(QUERY_COMMANDS):
        reply = request(server.endpoint, {"v": 1, "id": cmd, "cmd": cmd})
        assert reply["ok"] and reply["message"] == f"{cmd} done"
    assert not handler.release.is_set()  # the plan is still under way
    holder.send("own status", "status")  # behind its own client's plan: it reflects it
    handler.release.set()
    assert [holder.receive()["id"] for _ in range(2)] == ["block", "own status"]
    holder.close()


@pytest.mark.parametrize("urgent", ["stop", "abort", "estop"])
def test_an_urgent_command_cancels_queued_motion_from_every_client(server, handler, urgent) -> None:
    holder = blocked(server, handler)
    mover, player = Client(server.endpoint), Client(server.endpoint)
    for number in range(3):
        mover.send(f"move{number}", "move", pose=POSE)
    mover.send("frames", "frames")
    player.send("play", "play", sequence="x_sweep")
    player.send("lock", "leg_lock", leg=2)
    player.send("validate", "validate_pose", pose=POSE)
    # Each client's requests arrive in order: once its last is queued, all are.
    mover.send("marker-m", "pause")
    player.send("marker-p", "pause")
    wait_queued(server, 9)
    reply = request(server.endpoint, {"v": 1, "id": "urgent", "cmd": urgent})
    assert reply["ok"]
    cancelled = {**mover.replies(3), **player.replies(2)}
    assert set(cancelled) == {"move0", "move1", "move2", "play", "lock"}
    for item in cancelled.values():
        assert item["error"]["code"] == "cancelled" and urgent in item["error"]["message"], item
    handler.release.set()
    kept = {**mover.replies(2), **player.replies(2)}
    assert all(reply["ok"] for reply in kept.values()) and set(kept) == {"frames", "marker-m", "validate", "marker-p"}
    assert not {"move0", "move1", "move2", "play", "lock"} & set(handler.ids())  # never carried out
    for client in (holder, mover, player):
        client.close()


def test_an_estops_reply_goes_before_the_motion_it_cancels_in_transport(server, handler) -> None:
    """Found from outside: an E-stop's reply waited until thousands of requests read after it
    were answered, 2 to 4 s under a flood. (A stop's still waits: what a client sends once it
    has seen it must not be cancelled by it; a motion sent after an E-stop's reply is
    refused while it is latched, either way.)"""
    client = Client(server.endpoint)
    try:
        client.send("block-estop", "estop")  # the socket thread carries it out, held in the handler
        assert handler.entered.wait(WAIT_S)
        for number in range(20):
            client.send(f"move{number}", "move", pose=POSE)  # in transport meanwhile
        time.sleep(0.2)  # lets them arrive: the old order showed only for those that had
        handler.release.set()
        replies = [client.receive() for _ in range(21)]
    finally:
        client.close()
    assert replies[0]["id"] == "block-estop" and replies[0]["ok"], [reply["id"] for reply in replies]
    assert sorted(reply["id"] for reply in replies[1:]) == sorted(f"move{number}" for number in range(20))


def wait_queued(server: ApiServer, count: int) -> None:
    """Wait until ``count`` requests wait in the server's queues (its own counter)."""
    wait_until(lambda: server._queued >= count, f"{count} requests queued", WAIT_S, poll_s=0.005,
               seen=lambda: f"{server._queued} queued")


def test_a_flooding_client_gets_busy_and_others_are_served_in_turn(server, handler) -> None:
    holder = blocked(server, handler)
    flooder, other = Client(server.endpoint), Client(server.endpoint)
    extra = 5
    for number in range(MAX_QUEUED_PER_CLIENT + extra):
        flooder.send(number, "validate_pose", pose=POSE)
    busy = [flooder.receive() for _ in range(extra)]
    assert {reply["id"] for reply in busy} == set(range(MAX_QUEUED_PER_CLIENT, MAX_QUEUED_PER_CLIENT + extra))
    for reply in busy:
        assert reply["error"]["code"] == "busy", reply
        assert f"{MAX_QUEUED_PER_CLIENT} requests queued from this client" in reply["error"]["message"]
    other.send("other", "frames")
    wait_queued(server, MAX_QUEUED_PER_CLIENT + 1)
    handler.release.set()
    assert other.receive()["ok"]
    assert "other" in handler.ids()[:3]  # its turn came after one of the flooder's, not after 32
    assert len(flooder.replies(MAX_QUEUED_PER_CLIENT)) == MAX_QUEUED_PER_CLIENT
    for client in (holder, flooder, other):
        client.close()


@pytest.fixture
def small_queues(monkeypatch) -> None:
    """A total of 4 and a ceiling of 6 (the rules, with fewer sockets)."""
    import hexactl.adapters.api.server as server_module

    monkeypatch.setattr(server_module, "MAX_QUEUED", 4)
    monkeypatch.setattr(server_module, "MAX_QUEUED_CEILING", 6)


@pytest.mark.usefixtures("small_queues")
def test_the_total_queue_refuses_clients_at_their_share_and_takes_the_others(server, handler) -> None:
    """Found from outside: eight clients of 32 requests each filled the queue of 256, and
    every other client's every command (an operator's reset) was refused busy."""
    holder = blocked(server, handler)
    clients = [Client(server.endpoint) for _ in range(2)]
    for client in clients:
        for number in range(2):
            client.send(number, "validate_pose", pose=POSE)
    wait_queued(server, 4)
    clients[0].send("over", "validate_pose", pose=POSE)  # 2 of 4 from 2 clients: its share
    reply = clients[0].receive()
    assert reply["id"] == "over" and reply["error"]["code"] == "busy", reply
    assert reply["error"]["message"] == ("4 requests queued from 2 clients, 2 of them from this one (its share: 2); "
                                         "wait for replies before sending more")
    late = Client(server.endpoint)
    late.send("late", "reset")  # none of its own queued: taken
    wait_queued(server, 5)
    handler.release.set()
    assert late.receive()["ok"]
    for client in clients:
        assert len(client.replies(2)) == 2
    for client in (holder, late, *clients):
        client.close()


@pytest.mark.usefixtures("small_queues")
def test_the_total_queue_is_bounded_for_every_client(server, handler) -> None:
    holder = blocked(server, handler)
    clients = [Client(server.endpoint) for _ in range(7)]
    for number, client in enumerate(clients[:6]):
        client.send(number, "validate_pose", pose=POSE)
        wait_queued(server, number + 1)
    clients[6].send("late", "validate_pose", pose=POSE)  # none of its own, but the ceiling reached
    reply = clients[6].receive()
    assert reply["error"]["code"] == "busy" and reply["error"]["message"] == (
        "6 requests queued from 6 clients, the most the service keeps; wait a moment and send it again")
    assert reply["error"]["details"] == {"limit_per_client": MAX_QUEUED_PER_CLIENT, "limit": 4, "ceiling": 6}
    handler.release.set()
    for client in clients[:6]:
        assert client.receive()["ok"]
    for client in (holder, *clients):
        client.close()


def test_a_request_past_its_deadline_is_answered_expired_and_not_carried_out(server, handler) -> None:
    holder = blocked(server, handler)
    client = Client(server.endpoint)
    sent_at = time.monotonic_ns()
    client.send("late", "validate_pose", pose=POSE, deadline_ms=1)
    client.send("in time", "validate_pose", pose=POSE, deadline_ms=60_000)
    client.send("marker", "stop")  # answered at once (and cancels no query): both were received before it
    assert client.receive()["id"] == "marker"
    received_by = time.monotonic_ns()
    while time.monotonic_ns() < received_by + 2_000_000:  # the 1 ms deadline is over
        time.sleep(0.001)
    handler.release.set()
    replies = client.replies(2)
    assert replies["late"]["error"]["code"] == "expired" and "deadline_ms (1)" in replies["late"]["error"]["message"]
    assert replies["in time"]["ok"]
    assert "late" not in handler.ids()
    (deadline,) = [deadline for cmd, request_id, deadline in handler.done if request_id == "in time"]
    assert sent_at + 60_000_000_000 <= deadline <= received_by + 60_000_000_000  # from when the service received it
    holder.close()
    client.close()


def test_a_request_past_its_expires_at_is_answered_expired_however_late_it_was_read(server, handler) -> None:
    """Found from outside: deadline_ms counts from the service's receipt, so a move sent
    into a frozen API process (SIGSTOP, or a starved host), whose client had given up, ran
    when the process resumed. expires_at is the sender's own time: one that passed before
    the request's turn expires it, and one passed on arrival says so."""
    holder = blocked(server, handler)
    client = Client(server.endpoint)
    # A second to arrive in, however busy the host: it expires while queued, not on arrival
    expires_at = time.time() + 1.0
    client.send("queued", "validate_pose", pose=POSE, expires_at=expires_at, deadline_ms=60_000)
    client.send("late on arrival", "validate_pose", pose=POSE, expires_at=time.time() - 2.0)
    client.send("in time", "validate_pose", pose=POSE, expires_at=time.time() + 60.0)
    client.send("marker", "stop")  # answered at once: the three were received before it
    assert client.receive()["id"] == "marker"
    while time.time() <= expires_at:  # by this host's clock, as the service judges it
        time.sleep(0.01)
    handler.release.set()
    replies = client.replies(3)
    queued, arrived_late = replies["queued"]["error"], replies["late on arrival"]["error"]
    assert queued["code"] == arrived_late["code"] == "expired", replies
    assert queued["message"].startswith("validate_pose expired, not carried out: its expires_at (") \
        and "by this host's clock) passed" in queued["message"], queued
    assert "it arrived 2" in arrived_late["message"] and "or the sender's clock is behind this host's" \
        in arrived_late["message"], arrived_late
    assert replies["in time"]["ok"] and handler.ids()[-1] == "in time"
    assert "queued" not in handler.ids() and "late on arrival" not in handler.ids()
    holder.close()
    client.close()


def test_an_expires_at_beyond_an_hour_is_refused_as_no_unix_time_in_seconds(server, handler) -> None:
    in_ms = time.time() * 1000.0
    reply = request(server.endpoint, {"v": 1, "id": 1, "cmd": "status", "expires_at": in_ms})
    assert reply["error"]["code"] == "invalid_request" and reply["id"] == 1
    assert "beyond the longest deadline, an hour: a Unix time in s, as time.time() gives it (not ms)" \
        in reply["error"]["message"]
    assert handler.done == []


def test_without_deadline_the_handler_gets_none(server, handler) -> None:
    assert request(server.endpoint, {"v": 1, "id": 1, "cmd": "status"})["ok"]
    assert handler.done == [("status", 1, None)]


def test_the_client_sets_its_deadline_from_its_timeout(server, handler) -> None:
    before = time.monotonic_ns()
    with HexactlClient(server.endpoint, timeout_s=2.0) as client:
        client.call("status")
    after = time.monotonic_ns()
    ((_, _, deadline),) = handler.done
    # 2 s less 20 %, by deadline_ms and expires_at alike (the earlier counts; one wall-clock
    # reading apart: time.time()'s resolution)
    assert before + 1_600_000_000 - 1_000_000 <= deadline <= after + 1_600_000_000
    assert deadline_ms(2.0) == 1600.0
    assert deadline_ms(0.1) == 100.0 - DEADLINE_MARGIN_MIN_MS  # the margin at least 50 ms
    assert deadline_ms(0.06) == 30.0  # and at most half the timeout


def test_the_watchdog_reports_a_stuck_handler_and_stops_go_on(handler) -> None:
    context = zmq.Context()
    stuck = threading.Event()
    reports: list[str] = []

    def on_stuck(description: str) -> None:
        reports.append(description)
        stuck.set()

    served = ApiServer(context, LOCAL, handler, handler_timeout_s=0.2, on_stuck=on_stuck)
    served.start()
    try:
        holder = blocked(served, handler)
        assert stuck.wait(WAIT_S)
        assert reports == ['the API worker has been handling validate_pose (id "block") for more than 0.2 s: the API is '
                           'stuck']
        assert request(served.endpoint, {"v": 1, "id": 2, "cmd": "estop"})["ok"]
        holder.close()
    finally:
        closing = threading.Thread(target=served.close)
        closing.start()
        closing.join(WAIT_S)  # bounded although the worker is still held
        assert not closing.is_alive()
        handler.release.set()
        context.term()
    assert len(reports) == 1  # once per stuck request


# -- the smaller findings ------------------------------------------------------------------


def test_duplicate_keys_are_refused_naming_the_key(server) -> None:
    body = b'{"v": 1, "id": 7, "cmd": "move", "pose": [0, 0, 0, 0, 0, 0], "pose": [80, 0, 0, 0, 0, 0]}'
    with zmq.Context.instance().socket(zmq.DEALER) as socket:
        socket.linger = 0
        socket.connect(server.endpoint)
        socket.send(body)
        assert socket.poll(WAIT_S * 1000)
        reply = json.loads(socket.recv())
    assert reply["error"]["code"] == "invalid_request" and "'pose' appears twice" in reply["error"]["message"]


def test_a_huge_duration_is_an_invalid_request_naming_the_bound(server, handler) -> None:
    reply = request(server.endpoint, {"v": 1, "id": 1, "cmd": "move", "pose": POSE, "duration": 1e200})
    assert reply["error"]["code"] == "invalid_request"
    assert f"less than or equal to {MAX_MOTION_S:g}" in reply["error"]["message"]
    assert handler.done == []


def test_huge_dwells_are_refused(server, handler) -> None:
    sequence = {"name": "long", "waypoints": [{"pose": POSE, "dwell": 1e308}, {"pose": POSE, "dwell": 1e308}]}
    reply = request(server.endpoint, {"v": 1, "id": 1, "cmd": "play", "sequence": sequence})
    assert reply["error"]["code"] == "invalid_request" and "less than or equal to 86400" in reply["error"]["message"]
    with pytest.raises(SequenceError, match="86400"):
        sequence_from_toml('name = "long"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\ndwell = 1e308\n')
    with pytest.raises(SequenceError, match="600"):
        sequence_from_toml('name = "slow"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\nduration = 1e200\n')


def test_a_motion_request_being_planned_when_a_stop_arrives_is_stopped_again(server, handler) -> None:
    mover = Client(server.endpoint)
    mover.send("block-move", "move", pose=POSE)
    assert handler.entered.wait(WAIT_S)  # the worker is inside the move's handler
    assert request(server.endpoint, {"v": 1, "id": "stop", "cmd": "stop"})["ok"]
    handler.release.set()
    reply = mover.receive()
    assert reply["error"]["code"] == "cancelled" and "while it was being planned" in reply["error"]["message"]
    assert [(cmd, request_id) for cmd, request_id, _ in handler.done] == [("stop", "stop"), ("move", "block-move"),
                                                                          ("stop", None)]
    mover.close()


@pytest.fixture
def failing_reads(monkeypatch) -> None:
    """Reading a request whose body holds "fail" raises, as a defect of the server would."""
    import hexactl.adapters.api.server as server_module

    decode = server_module.decode_body

    def failing(body):
        if b"fail" in body[-1]:
            raise RecursionError("maximum recursion depth exceeded")
        return decode(body)

    monkeypatch.setattr(server_module, "decode_body", failing)


@pytest.mark.usefixtures("failing_reads")
def test_a_request_the_socket_thread_fails_on_is_answered_and_the_next_is_served(server) -> None:
    """A defect met reading one request is answered internal_error and logged; the thread that
    reads every request, an E-stop's, goes on (found from outside: one request killed it)."""
    client = Client(server.endpoint)
    try:
        client.send("fail", "status")
        reply = client.receive()
        assert reply["error"]["code"] == "internal_error" and "RecursionError" in reply["error"]["message"]
        client.send("after", "estop")
        assert client.receive()["ok"]
    finally:
        client.close()


def test_a_socket_thread_that_fails_ends_the_process_as_a_stuck_worker_does(monkeypatch) -> None:
    """Had it died, no request would be answered again while the service ran on."""
    import hexactl.adapters.api.server as server_module

    stuck = []
    monkeypatch.setattr(server_module.zmq, "Poller", lambda: (_ for _ in ()).throw(MemoryError("no poller")))
    context = zmq.Context()
    served = ApiServer(context, LOCAL, BlockingHandler(), on_stuck=stuck.append)
    try:
        served.start()
        wait_until(lambda: stuck, "the failure reported", WAIT_S)
    finally:
        served.close()
        context.term()
    assert stuck == ["the API's socket thread failed (MemoryError: no poller): no request would be answered again"]


@pytest.mark.usefixtures("failing_reads")
def test_a_request_that_fails_in_an_estops_drain_is_answered_and_the_drain_goes_on(server, handler) -> None:
    """Found reading the code from outside: the drain's requests were read outside the guard,
    so one that failed ended the drain, its client unanswered and the E-stop's answered twice."""
    stopper, other = Client(server.endpoint), Client(server.endpoint)
    try:
        stopper.send("block-estop", "estop")
        assert handler.entered.wait(WAIT_S)
        other.send("fail", "status")
        time.sleep(0.2)  # lets it arrive: read in the drain, or after it, its reply is the same
        handler.release.set()
        assert stopper.receive()["id"] == "block-estop"
        reply = other.receive()
        assert reply["error"]["code"] == "internal_error" and "RecursionError" in reply["error"]["message"]
        stopper.send("after", "status")
        assert stopper.receive()["id"] == "after"  # the E-stop's client had one reply, not two
    finally:
        stopper.close()
        other.close()
