"""A page's command has a time to live in the dashboard, counted from when the dashboard read
it: the page's own timeout (the dashboard's ``--timeout``, which the page is told in its
``hello``), one deadman period for a jog that moves. One still queued when it is up is never
sent and is answered ``expired``; one sent carries what is left of it as its ``deadline_ms``.

Found from outside: the dashboard queued commands in its thread pools with no such limit
and the API client counted its deadline from when a request left the queue, so a move
queued behind an API stalled 17 s (or behind 12 other commands) ran after the page had
said "timeout", and jog renewals queued during a stall started a jog after the page had
told the operator it was released.

The service is a fake whose answers the test holds back (a deterministic stall), or the
real one with its API process stopped (SIGSTOP) as the review did. Nothing is judged by
how long anything took: by what reached the service, the replies, and the platform's
commanded pose; the waits bound hangs only.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from hexactl.adapters.api.client import HexactlClient, deadline_ms
from hexactl.adapters.web.bridge import (COMMAND_WORKERS, JOG_DEADMAN_S, MAX_JOG_DEADMAN_S, ServiceBridge,
                                         ServiceEndpoints)
from tests.reliability.support import enable
from tools.browser import dashboard, page_constant
from tools.serving import serve, spawned_children, wait_until

WAIT_S = 60.0  # bounds a hang only


class HeldService:
    """The API as the bridge's workers reach it: each request is recorded (its command,
    fields and the client's wait) and answered only once :attr:`answers` is set, but for
    ``estop``, answered at once; a jog's reply names :attr:`deadman_s`."""

    def __init__(self, deadman_s: float = JOG_DEADMAN_S) -> None:
        self.deadman_s = deadman_s
        self.answers = threading.Event()
        self.sent: list[tuple[str, dict[str, Any], float]] = []
        self.lock = threading.Lock()

    def connect(self, kind: type, endpoint: str, *, timeout_s: float, name: str) -> Any:
        return self.Client(self, timeout_s)

    def commands(self) -> list[str]:
        with self.lock:
            return [cmd for cmd, _, _ in self.sent]

    class Client:
        def __init__(self, service: HeldService, timeout_s: float) -> None:
            self.service, self.timeout_s = service, timeout_s

        def __enter__(self) -> HeldService.Client:
            return self

        def __exit__(self, *exception: object) -> None:
            pass

        def request(self, cmd: str, **fields: Any) -> dict[str, Any]:
            with self.service.lock:
                self.service.sent.append((cmd, fields, self.timeout_s))
            if cmd != "estop":
                assert self.service.answers.wait(WAIT_S), "the test never let the service answer"
            return {"ok": True, "cmd": cmd, **({"deadman_s": self.service.deadman_s} if cmd == "jog" else {})}


@contextmanager
def bridge_to(service: HeldService, timeout_s: float) -> Iterator[ServiceBridge]:
    bridge = ServiceBridge(ServiceEndpoints("api", "telemetry", timeout_s, connect=service.connect))
    try:
        yield bridge
    finally:
        service.answers.set()
        bridge.close()


async def taught_its_deadman(bridge: ServiceBridge, service: HeldService) -> None:
    """The bridge told the service's deadman by a jog answered at once, then the service held
    again and what it received forgotten. A long deadman (the service's bound) lets a jog
    wait for the jog worker on a busy host: what expires then is what waits behind a held one."""
    service.answers.set()
    assert (await asyncio.wait_for(bridge.command("jog", {"velocity": [0, 0, 1, 0, 0, 0]}), WAIT_S))["ok"]
    service.answers.clear()
    with service.lock:
        service.sent.clear()


async def until(condition: Any, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"never: {what}"
        await asyncio.sleep(0.005)


def test_a_command_still_queued_when_the_pages_timeout_is_up_is_never_sent_and_says_so() -> None:
    """Every worker is held by a request the service does not answer; a move queued behind
    them is answered ``expired`` (not carried out) and never reaches the service, even once
    it answers again."""
    service = HeldService()

    async def scenario(bridge: ServiceBridge) -> dict[str, Any]:
        ahead = [asyncio.create_task(bridge.command("status", {})) for _ in range(COMMAND_WORKERS)]
        await until(lambda: len(service.sent) == COMMAND_WORKERS, "every worker holding a status")
        move = await asyncio.wait_for(bridge.command("move", {"pose": [0, 0, 10, 0, 0, 0]}), WAIT_S)
        service.answers.set()
        assert all(reply["ok"] for reply in await asyncio.wait_for(asyncio.gather(*ahead), WAIT_S))
        for _ in range(3):  # a worker freed now takes what is still in its queue: the move, passed by
            await asyncio.wait_for(bridge.command("status", {}), WAIT_S)
        return move

    with bridge_to(service, timeout_s=1.0) as bridge:
        move = asyncio.run(scenario(bridge))
    assert move["ok"] is False and move["error"]["code"] == "expired", move
    assert "not carried out" in move["error"]["message"] and "waited" in move["error"]["message"]
    assert "move" not in service.commands()


def test_a_command_sent_carries_the_time_left_since_the_page_sent_it_as_its_deadline() -> None:
    """Read 20 s ago by a dashboard whose page waits 60 s: the service is given at most
    what is left (40 s, less the client's margin) and the client waits no longer; read 59 s
    ago, it is not sent at all."""
    service = HeldService()
    service.answers.set()

    async def read_ago(seconds: float, cmd: str, fields: dict[str, Any]) -> dict[str, Any]:
        return await bridge.command(cmd, fields, received=time.monotonic() - seconds)

    with bridge_to(service, timeout_s=60.0) as bridge:
        assert asyncio.run(read_ago(20.0, "move", {"pose": [0] * 6}))["ok"]
        late = asyncio.run(read_ago(59.0, "move", {"pose": [1] * 6}))
    (cmd, fields, wait_s), = service.sent
    assert cmd == "move" and fields["pose"] == [0] * 6
    assert 0 < wait_s <= 40.0 and 0 < fields["deadline_ms"] <= deadline_ms(40.0)
    assert late["error"]["code"] == "expired" and "not carried out" in late["error"]["message"]


@pytest.mark.parametrize(("given", "sent"), [(3_600_000, deadline_ms(30.0)), (250, 250)])
def test_a_pages_own_deadline_is_kept_only_when_shorter_than_the_dashboards(given: float, sent: float) -> None:
    service = HeldService()
    service.answers.set()
    with bridge_to(service, timeout_s=30.0) as bridge:
        assert asyncio.run(bridge.command("move", {"pose": [0] * 6, "deadline_ms": given}))["ok"]
    (_, fields, _), = service.sent
    assert fields["deadline_ms"] <= sent


@pytest.mark.parametrize("given", ["3600000", True, None, [1]])
def test_a_deadline_that_is_no_number_is_refused_unsent(given: object) -> None:
    service = HeldService()
    service.answers.set()
    with bridge_to(service, timeout_s=30.0) as bridge:
        reply = asyncio.run(bridge.command("move", {"pose": [0] * 6, "deadline_ms": given}))
    if given is None:  # no deadline of the page's own: the dashboard's
        assert reply["ok"] and service.sent[0][1]["deadline_ms"] <= deadline_ms(30.0)
    else:
        assert reply["error"]["code"] == "invalid_request" and service.sent == []


def test_jog_renewals_queued_longer_than_the_deadman_are_never_sent_but_the_release_is() -> None:
    """A press held by a stalled service on the one jog worker: the renewals queued behind
    it are answered ``expired`` (the dashboard waits for them at most one deadman period)
    and never sent, the press itself was given at most one deadman; the release behind
    them all is carried out (what stops motion has no time to live), last."""
    service = HeldService(deadman_s=MAX_JOG_DEADMAN_S)
    moving = {"velocity": [0, 0, 5, 0, 0, 0], "frame": "zero"}

    async def scenario(bridge: ServiceBridge) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        await taught_its_deadman(bridge, service)
        press = asyncio.create_task(bridge.command("jog", moving))
        await until(lambda: service.sent, "the press sent")
        renewals = await asyncio.wait_for(asyncio.gather(*(bridge.command("jog", moving) for _ in range(3))), WAIT_S)
        release = asyncio.create_task(bridge.command("jog", {"velocity": [0] * 6, "frame": "zero"}))
        service.answers.set()
        assert (await asyncio.wait_for(press, WAIT_S))["ok"]
        return renewals, await asyncio.wait_for(release, WAIT_S)

    with bridge_to(service, timeout_s=30.0) as bridge:
        renewals, release = asyncio.run(scenario(bridge))
    assert [reply["error"]["code"] for reply in renewals] == ["expired"] * 3, renewals
    assert release["ok"]
    assert [fields["velocity"] for _, fields, _ in service.sent] == [moving["velocity"], [0] * 6]
    (_, press, press_wait_s) = service.sent[0]
    assert press_wait_s <= service.deadman_s and press["deadline_ms"] <= service.deadman_s * 1000.0


def test_an_e_stop_is_carried_out_while_other_commands_are_stuck_queued() -> None:
    """Every command worker and the jog worker held by the stalled service, more queued
    behind them: the E-stop goes on its own worker, at once."""
    service = HeldService(deadman_s=MAX_JOG_DEADMAN_S)

    async def scenario(bridge: ServiceBridge) -> dict[str, Any]:
        await taught_its_deadman(bridge, service)
        stuck = [asyncio.create_task(bridge.command("move", {"pose": [0] * 6})) for _ in range(3 * COMMAND_WORKERS)]
        stuck += [asyncio.create_task(bridge.command("jog", {"velocity": [0, 0, 5, 0, 0, 0]})) for _ in range(3)]
        await until(lambda: len(service.sent) == COMMAND_WORKERS + 1, "every worker held")
        stopped = await asyncio.wait_for(bridge.command("estop", {}), WAIT_S)
        assert not service.answers.is_set() and all(not task.done() for task in stuck[:COMMAND_WORKERS])
        service.answers.set()
        await asyncio.wait_for(asyncio.gather(*stuck), WAIT_S)
        return stopped

    with bridge_to(service, timeout_s=30.0) as bridge:
        stopped = asyncio.run(scenario(bridge))
    assert stopped["ok"] and "estop" in service.commands()


def test_the_page_waits_as_long_as_the_dashboard_says_in_its_hello(tmp_path: Path) -> None:
    """The page's command timeout is the dashboard's ``--timeout``, sent first on its
    WebSocket; the page declares no timeout of its own (it was 15 s while the dashboard
    gave the API 40)."""
    with pytest.raises(LookupError):
        page_constant("COMMAND_TIMEOUT_MS")
    with dashboard("tcp://127.0.0.1:9", "tcp://127.0.0.1:9", "--timeout", "40") as board:
        with connect(board.url.replace("http", "ws", 1) + "ws", open_timeout=WAIT_S) as page:
            assert json.loads(page.recv(WAIT_S)) == {"type": "hello", "command_timeout_ms": 40000.0}


# -- the service itself, its API process stopped as the review did -------------------------------


def messages_until(page: Any, wanted: Any, what: str, within_s: float = WAIT_S) -> dict[str, Any] | None:
    """The first message from ``page`` for which ``wanted(message)``, telemetry acknowledged;
    None if none within ``within_s``."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            message = json.loads(page.recv(0.2))
        except TimeoutError:
            continue
        if message["type"] == "telemetry":
            page.send(json.dumps({"type": "ack", "n": message["n"]}))
        if wanted(message):
            return message
    return None


@pytest.fixture(scope="module")
def stalled_rig(tmp_path_factory) -> Iterator[tuple[Any, Any, int]]:
    with serve(tmp_path_factory.mktemp("admission"), "--no-realtime") as served, \
            dashboard(served.api, served.telemetry, "--timeout", str(RIG_TIMEOUT_S)) as board:
        (api_process,) = spawned_children(served.process.pid)
        try:
            yield served, board, api_process
        finally:
            os.kill(api_process, signal.SIGCONT)


RIG_TIMEOUT_S = 10
"""The rig's dashboard's --timeout: its pages wait that long for a reply."""


def at_rest_enabled(api: str) -> HexactlClient:
    client = HexactlClient(api, timeout_s=30.0)
    state = client.call("status")["status"]["state"]
    if state in ("fault", "estop"):
        client.call("reset")
    enable(client)
    wait_until(lambda: client.call("status")["status"]["motion"] == "holding", "at rest", WAIT_S)
    return client


def dashboards_motion(client: HexactlClient, since: int) -> list[dict[str, Any]]:
    """The service's events after ``since`` (a seq) of motion the dashboard's pages set off."""
    events = client.call("events", after=since)["events"]
    return [event for event in events if (event.get("sender") or "").startswith("dashboard")
            and (event["code"] in ("move", "jog") or event["code"].startswith("jog"))]


def last_seq(client: HexactlClient) -> int:
    return max((event["seq"] for event in client.call("events", after=0)["events"]), default=0)


@contextmanager
def page_socket(board: Any) -> Iterator[Any]:
    """A page's WebSocket to ``board``, once the dashboard has telemetry."""
    with connect(board.url.replace("http", "ws", 1) + "ws", open_timeout=WAIT_S) as page:
        assert messages_until(page, lambda m: m["type"] == "link" and m["connected"], "the link"), "no link"
        yield page


def test_a_move_queued_behind_a_stalled_api_is_refused_while_it_is_stalled_and_never_runs(stalled_rig) -> None:
    """The review's late_move.py: 12 status requests ahead of a move, the API process
    stopped until the move's reply has come. It comes, ``expired``; once the API runs again
    the move is not carried out. (Before: the move was sent when a worker freed, 30 s on,
    and ran when the API resumed.)"""
    served, board, api_process = stalled_rig
    with at_rest_enabled(served.api) as client:
        before, since = client.call("status")["status"]["pose_command"], last_seq(client)
        with page_socket(board) as page:
            replies: dict[int, dict[str, Any]] = {}

            def collect(message: dict[str, Any]) -> bool:
                if message["type"] == "reply":
                    replies[message["id"]] = message
                return 1 in replies

            os.kill(api_process, signal.SIGSTOP)
            try:
                for number in range(12):
                    page.send(json.dumps({"type": "command", "id": 100 + number, "cmd": "status"}))
                page.send(json.dumps({"type": "command", "id": 1, "cmd": "move", "pose": [0, 0, 20, 0, 0, 0],
                                      "duration": 1.0}))
                messages_until(page, collect, "the move's reply")
                move = replies.get(1)
            finally:
                os.kill(api_process, signal.SIGCONT)
            while len(replies) < 13:  # every request the dashboard had out answered: nothing is on its way
                assert messages_until(page, lambda m: collect(m) and len(replies) == 13, "every reply"), replies
        assert move is not None and move["reply"]["error"]["code"] == "expired", move
        assert "not carried out" in move["reply"]["error"]["message"]
        assert dashboards_motion(client, since) == []
        assert client.call("status")["status"]["pose_command"] == before


def test_jog_requests_sent_into_a_stalled_api_start_no_jog_when_it_resumes(stalled_rig) -> None:
    """The review's late_jog.py: a press and two renewals while the API process is
    stopped; the page stops renewing (at 2 s without live data) and tells the operator the
    jog is released; the API resumes some seconds later. Each jog is answered within its
    deadman period, not carried out, and no jog starts when the API resumes. (Before: they
    waited on the one jog worker, the first for the whole --timeout, and the API resuming
    meanwhile carried it out.)"""
    served, board, api_process = stalled_rig
    with at_rest_enabled(served.api) as client:
        before, since = client.call("status")["status"]["pose_command"], last_seq(client)
        with page_socket(board) as page:
            os.kill(api_process, signal.SIGSTOP)
            replies: dict[int, dict[str, Any]] = {}
            try:
                for number in range(3):
                    page.send(json.dumps({"type": "command", "id": number, "cmd": "jog",
                                          "velocity": [10, 0, 0, 0, 0, 0], "frame": "zero"}))
                while len(replies) < 3 and (reply := messages_until(
                        page, lambda m: m["type"] == "reply", "a jog's reply", STALL_S)) is not None:
                    replies[reply["id"]] = reply["reply"]
            finally:
                os.kill(api_process, signal.SIGCONT)  # the API resumes: at the latest STALL_S on
            while len(replies) < 3:  # what was still out then (before: the first jog, carried out now)
                reply = messages_until(page, lambda m: m["type"] == "reply", "a jog's reply")
                assert reply is not None, "a jog never answered"
                replies[reply["id"]] = reply["reply"]
        assert all(not reply["ok"] for reply in replies.values()), replies
        assert {reply["error"]["code"] for reply in replies.values()} <= {"expired", "unavailable"}, replies
        assert dashboards_motion(client, since) == []
        status = client.call("status")["status"]
        assert status["pose_command"] == before and status["jog"] is None, status


STALL_S = 0.8 * RIG_TIMEOUT_S
"""How long the API stays stopped at most in the jog test: past the page's 2 s without live
data, within the rig's --timeout (a request the dashboard sent when the stall began is
still waited for then: before, it was carried out when the API resumed)."""
