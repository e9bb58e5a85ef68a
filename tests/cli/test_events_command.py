"""``hexactl events`` on a real ``hexactl serve``: the loop's latest events with who sent the
command behind each, once or followed as they come (--follow), as text or JSON."""

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
    wait_for(lambda: any(event["code"] == "stop" and event["sender"] == f"{ANN} (127.0.0.1)"
                         for event in ann.call("status")["status"]["events"]), "the stop's event")
    capsys.readouterr()
    started = time.time()
    assert main(["events", "--telemetry", served.telemetry, "--json"]) == 0
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert 1 <= len(printed) <= 8 and [event["t"] for event in printed] == sorted(event["t"] for event in printed)
    stop = [event for event in printed if event["code"] == "stop"][-1]
    assert stop["sender"] == f"{ANN} (127.0.0.1)" and stop["message"] == "any motion under way brakes to rest"
    assert stop["at"] <= started + 1.0  # this host's clock, when it happened: before the command ran

    assert main(["events", "--telemetry", served.telemetry]) == 0
    text = [line for line in capsys.readouterr().out.splitlines() if line.split()[1:2] == ["stop"]][-1]
    assert text.endswith(f" any motion under way brakes to rest  (sent by {ANN} (127.0.0.1))"), text


def test_follow_prints_each_new_event_once_as_it_comes_until_ctrl_c(served, ann) -> None:
    follower = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "events", "--follow", "--json",
                                 "--telemetry", served.telemetry], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, cwd=Path(__file__).resolve().parents[2])
    lines: list[dict] = []
    reader = threading.Thread(target=lambda: lines.extend(json.loads(line) for line in follower.stdout), daemon=True)
    reader.start()
    try:
        wait_for(lambda: lines, "the latest events printed")  # there is at least the enable
        shown = len(lines)
        for _ in range(3):
            ann.call("stop")
        wait_for(lambda: sum(1 for event in lines[shown:] if event["code"] == "stop") == 3, "three new stops",
                 seen=lambda: lines[shown:])
        assert all(event["sender"] == f"{ANN} (127.0.0.1)" for event in lines[shown:] if event["code"] == "stop")
        assert len({(e["t"], e["code"], e["message"], e["sender"]) for e in lines}) == len(lines)  # each once
    finally:
        follower.send_signal(signal.SIGINT)
        follower.wait(HANG_S)
    assert follower.returncode == 130, follower.stderr.read()
