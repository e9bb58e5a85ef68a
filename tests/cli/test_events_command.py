"""``hexactl events`` on a real ``hexactl serve``: the loop's latest events with who sent the
command behind each, once or followed as they come (--follow), as text or JSON; a burst
printed whole, and what the loop no longer kept counted."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.cli.main import main
from hexactl.control.core import KEPT_EVENTS
from tests.api.test_service import wait_for
from tests.reliability.support import recover
from tools.serving import HANG_S, Served, serve

WAIT_S = 30.0
ANN = "ann at the bench"


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    with serve(tmp_path_factory.mktemp("events")) as running:
        yield running


@pytest.fixture
def ann(served: Served) -> Iterator[HexactlClient]:
    with HexactlClient(served.api, timeout_s=WAIT_S, name=ANN) as client:
        recover(client)
        yield client


def test_events_prints_the_latest_with_their_senders_and_exits(served, ann, capsys) -> None:
    ann.call("stop")
    stopped = time.time()  # the stop's event happened before this, on this host's clock
    ours = wait_for(lambda: next((event for event in reversed(ann.call("status")["status"]["events"])
                                  if event["code"] == "stop" and event["sender"] == f"{ANN} (127.0.0.1)"), None),
                    "the stop's event")
    # a second on the service's clock since: a line stamped when printed, not when it happened, is that late
    wait_for(lambda: ann.call("status")["status"]["t"] - ours["t"] >= 1.0, "a second since the stop")
    capsys.readouterr()
    started = time.time()
    assert main(["events", "--api", served.api, "--json"]) == 0
    reply_delay_bound = time.time() - started
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert 1 <= len(printed) <= 20 and [event["seq"] for event in printed] == list(range(printed[0]["seq"], printed[-1]["seq"] + 1))
    stop = [event for event in printed if event["code"] == "stop"][-1]
    assert stop["sender"] == f"{ANN} (127.0.0.1)" and stop["message"] == "any motion under way brakes to rest"
    # this host's clock when it happened: at most the reply's delay (bounded by the command's run) after it
    assert stop["at"] <= stopped + reply_delay_bound + 0.001, (stop, stopped, reply_delay_bound)  # at: to 1 ms

    assert main(["events", "--api", served.api]) == 0
    text = [line for line in capsys.readouterr().out.splitlines() if line.split()[1:2] == ["stop"]][-1]
    assert text.endswith(f" any motion under way brakes to rest  (sent by {ANN} (127.0.0.1))"), text


class Follower:
    """``hexactl events --follow --json`` in a process of its own, its lines read as they come."""

    def __init__(self, api: str) -> None:
        self.process = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "events", "--follow",
                                         "--json", "--api", api], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True, cwd=Path(__file__).resolve().parents[2])
        self.lines: list[dict] = []
        threading.Thread(target=lambda: self.lines.extend(json.loads(line) for line in self.process.stdout),
                         daemon=True).start()

    def interrupted(self) -> tuple[int, str]:
        """Ctrl-C: its exit status and what it said on stderr."""
        self.process.send_signal(signal.SIGINT)
        self.process.wait(HANG_S)
        return self.process.returncode, self.process.stderr.read()


@pytest.fixture
def follower(served: Served) -> Iterator[Follower]:
    running = Follower(served.api)
    try:
        yield running
    finally:
        if running.process.poll() is None:
            running.process.kill()
            running.process.wait(HANG_S)


def test_follow_prints_each_new_event_once_as_it_comes_until_ctrl_c(follower, ann) -> None:
    lines = follower.lines
    # Every event there is now printed (at least the enable): the first line alone left an
    # earlier test's stop, printed later, to count as new (seen in a busy host's run)
    last = ann.call("events", after=0)["last"]
    wait_for(lambda: lines and lines[-1]["seq"] >= last, "the latest events printed")
    shown = len(lines)
    for _ in range(3):
        ann.call("stop")
    wait_for(lambda: sum(1 for event in lines[shown:] if event["code"] == "stop") == 3, "three new stops",
             seen=lambda: lines[shown:])
    assert all(event["sender"] == f"{ANN} (127.0.0.1)" for event in lines[shown:] if event["code"] == "stop")
    assert [event["seq"] for event in lines] == list(range(lines[0]["seq"], lines[-1]["seq"] + 1))  # each once
    status, said = follower.interrupted()
    assert status == 130, said


def _burst_while_frozen(follower: Follower, client: HexactlClient, stops: int) -> int:
    """``stops`` stops sent while the follower is frozen (SIGSTOP), so that they all come
    between two of its asks; the number of the last event it printed before."""
    # every event so far printed and read here first: a first batch read here only in part
    # (a busy host) made its rest look like events printed after the burst
    newest = client.call("events", after=0)["last"]
    wait_for(lambda: follower.lines and follower.lines[-1]["seq"] >= newest, f"the events up to {newest} printed",
             seen=lambda: follower.lines[-3:])
    seen = follower.lines[-1]["seq"]
    follower.process.send_signal(signal.SIGSTOP)
    try:
        for _ in range(stops):
            client.call("stop")
    finally:
        follower.process.send_signal(signal.SIGCONT)
    return seen


def test_follow_prints_a_burst_whole_though_it_outnumbers_what_telemetry_carries(follower, ann) -> None:
    seen = _burst_while_frozen(follower, ann, 20)  # telemetry carries the latest 8: --follow once showed those only
    wait_for(lambda: sum(1 for event in follower.lines if event["seq"] > seen and event["code"] == "stop") == 20,
             "the burst's twenty stops", seen=lambda: follower.lines[-3:])
    new = [event["seq"] for event in follower.lines if event["seq"] > seen]
    assert new == list(range(seen + 1, new[-1] + 1))
    status, said = follower.interrupted()
    assert status == 130 and "came and went" not in said, said


def test_follow_counts_the_events_of_a_burst_the_loop_no_longer_kept(follower, ann) -> None:
    seen = _burst_while_frozen(follower, ann, KEPT_EVENTS + 6)
    last = ann.call("events", after=seen)["last"]
    wait_for(lambda: follower.lines[-1]["seq"] >= last, "the burst printed", seen=lambda: follower.lines[-3:])
    printed = [event["seq"] for event in follower.lines if seen < event["seq"] <= last]
    assert printed == list(range(last - KEPT_EVENTS + 1, last + 1))  # all the loop kept, each once
    status, said = follower.interrupted()
    assert status == 130 and f"hexactl events: {printed[0] - seen - 1} events came and went between two asks" in said


def test_follow_notices_a_restarted_service_however_many_events_it_has_had_since(monkeypatch, capsys) -> None:
    """A service restarted between two asks numbers its events from 1 again: ``last`` below
    the ``after`` sent was the only sign, and a new run with more events than that had its
    first ones skipped, the rest printed as if nothing happened."""
    from hexactl.adapters.api import client as client_module

    def event(seq: int, code: str) -> dict:
        return {"seq": seq, "t": 10.0 + seq, "code": code, "message": code, "sender": None}

    first_run = [event(1, "enabled"), event(2, "stop")]
    second_run = [event(n, f"new{n}") for n in range(1, 6)]  # more than the first run's two
    replies = iter([("a1", first_run), ("b2", second_run), ("b2", second_run)])
    asked: list[int] = []

    class Client:
        def __init__(self, endpoint: str, **options: object) -> None:
            pass

        def __enter__(self) -> "Client":
            return self

        def __exit__(self, *exception: object) -> None:
            pass

        def request(self, cmd: str, after: int) -> dict:
            asked.append(after)
            try:
                run, events = next(replies)
            except StopIteration:
                raise KeyboardInterrupt from None  # Ctrl-C once the test's replies are out
            kept = [e for e in events if e["seq"] > after]
            return {"ok": True, "t": 20.0, "events": kept, "missed": 0, "last": events[-1]["seq"], "run": run}

    monkeypatch.setattr(client_module, "HexactlClient", Client)
    assert main(["events", "--follow", "--json", "--api", "tcp://127.0.0.1:1"]) == 130
    captured = capsys.readouterr()
    assert [json.loads(line)["code"] for line in captured.out.splitlines()] == [
        "enabled", "stop", "new1", "new2", "new3", "new4", "new5"]
    assert asked == [0, 2, 0, 5]
    assert "the service has restarted: its events from the start" in captured.err
