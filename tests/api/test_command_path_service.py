"""The command path against the real two-process ``hexactl serve`` (built-in simulator):
a move whose client timed out behind a flood never runs later, and an operator's ``stop``
ends the moves a vanished client left queued at once. Each test ends the service with
SIGTERM and checks that it exits and frees both ports."""

from __future__ import annotations

import functools
import json
import os
import signal
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import zmq

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber, deadline_ms
from tests.reliability.support import enable, tolerating_stalls
from tools.serving import serve, spawned_children, terminate, wait_until

WAIT_S = 60.0  # only turns a hang into a failure (the machine is shared and busy)
LOCAL = "tcp://127.0.0.1:*"
FLOODERS = 10
VALIDATIONS = 2
"""Each flooding client's validations: 30,000 samples each to check, so the move queued
behind them waits far beyond its client's 0.1 s on any machine, idle or busy."""


@contextmanager
def serving(directory: Path) -> Iterator[tuple[str, str]]:
    """``hexactl serve`` on random local ports: (API endpoint, telemetry endpoint). On the
    way out: SIGTERM, and it must keep the shutdown's promise (:mod:`tools.serving`)."""
    with serve(directory) as served:
        yield served.api, served.telemetry
        shutdown = terminate(served)
    assert shutdown.problems() == [], f"{shutdown}\n{served.log}"


def status(client: HexactlClient) -> dict[str, Any]:
    return client.call("status")["status"]


wait_for = functools.partial(wait_until, timeout_s=WAIT_S, poll_s=0.01)


def test_a_move_whose_client_timed_out_behind_a_flood_never_runs(tmp_path: Path) -> None:
    with serving(tmp_path) as (api, _), HexactlClient(api, timeout_s=WAIT_S) as operator:
        enable(operator)
        # A stall of a loaded host that latches a fault refuses every move, the timed-out one
        # too: then the whole flood again, from enabled and at rest (each failure printed).
        tolerating_stalls(operator, lambda: flood_then_move(api, operator))


def flood_then_move(api: str, operator: HexactlClient) -> None:
    wait_for(lambda: status(operator)["motion"] == "holding", "the platform at rest")
    start = status(operator)["pose_command"]
    context = zmq.Context.instance()
    flooders = []
    try:
        for number in range(FLOODERS):  # each validates a slow move: planning 60 s of motion, every cycle checked
            flooder = context.socket(zmq.DEALER)
            flooder.linger = 0
            flooders.append(flooder)
            flooder.connect(api)
            for request_id in range(VALIDATIONS):
                flooder.send(json.dumps({"v": 1, "id": request_id, "cmd": "validate_pose",
                                         "pose": [0, 0, number + 1, 0, 0, 0], "duration": 60.0}).encode())
        with HexactlClient(api, timeout_s=0.1) as mover:
            # The mover's own slow validations first: one client's requests are served in
            # order, so its move waits for them whatever the other clients' turns.
            for request_id in range(VALIDATIONS):
                mover.socket.send(json.dumps({"v": 1, "id": f"slow-{request_id}", "cmd": "validate_pose",
                                              "pose": [0, 0, -1, 0, 0, 0], "duration": 60.0}).encode())
            with pytest.raises(ServiceUnavailable):
                mover.call("move", pose=[80, 0, 0, 0, 0, 0])
            mover.timeout_s = 5 * WAIT_S  # behind the whole flood on a loaded host
            status(mover)  # answered after the move: the same client's requests are served in order
        for flooder in flooders:
            for _ in range(VALIDATIONS):
                assert flooder.poll(5 * WAIT_S * 1000)
                assert json.loads(flooder.recv())["ok"]
    finally:
        for flooder in flooders:
            flooder.close()
    record = status(operator)
    assert record["motion"] == "holding" and record["pose_command"] == pytest.approx(start, abs=1e-9), record
    # The service still moves for a client that waits long enough.
    operator.call("move", pose=[20, 0, 0, 0, 0, 0])
    wait_for(lambda: status(operator)["pose_command"][0] == pytest.approx(20.0, abs=1e-6), "the move")


def test_a_move_sent_into_a_frozen_api_process_expires_by_its_senders_clock(tmp_path: Path) -> None:
    """Found from outside: the API process frozen (SIGSTOP here; a starved host alike) while
    a client's move was on its way; the client timed out, and when the process resumed it
    received the move then, counted its deadline_ms from there and moved the platform.
    The client library's expires_at is the sender's own time: the move expires."""
    with serve(tmp_path) as served, HexactlClient(served.api, timeout_s=WAIT_S) as operator:
        enable(operator)
        [api_process] = spawned_children(served.process.pid)
        tolerating_stalls(operator, lambda: move_into_a_frozen_api(served.api, api_process, operator))
        shutdown = terminate(served)
    assert shutdown.problems() == [], f"{shutdown}\n{served.log}"


def move_into_a_frozen_api(api: str, api_process: int, operator: HexactlClient) -> None:
    wait_for(lambda: status(operator)["motion"] == "holding", "the platform at rest")
    start = status(operator)["pose_command"]
    since = operator.call("events", after=0)["last"]
    sender = zmq.Context.instance().socket(zmq.DEALER)  # a client that gave up, but reads the late reply
    sender.linger = 0
    sender.immediate = True
    sender.connect(api)
    try:
        wait_for(lambda: operator.call("status") and True, "connected")  # the service is up: the connection too
        os.kill(api_process, signal.SIGSTOP)
        try:
            timeout_s = 1.0  # as HexactlClient(timeout_s=1.0) sends it
            sender.send(json.dumps({"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, 20, 0, 0, 0], "duration": 1.0,
                                    "deadline_ms": deadline_ms(timeout_s),
                                    "expires_at": time.time() + deadline_ms(timeout_s) / 1000.0}).encode())
            time.sleep(1.5 * timeout_s)  # the sender gives up
        finally:
            os.kill(api_process, signal.SIGCONT)
        assert sender.poll(WAIT_S * 1000), "no reply to the move"
        reply = json.loads(sender.recv_multipart()[-1])
    finally:
        sender.close()
    assert reply["error"]["code"] == "expired" and "its expires_at" in reply["error"]["message"], reply
    assert [event for event in operator.call("events", after=since)["events"] if event["code"] == "move"] == []
    assert status(operator)["pose_command"] == start


def test_stop_ends_the_moves_a_vanished_client_left_queued(tmp_path: Path) -> None:
    with serving(tmp_path) as (api, telemetry), HexactlClient(api, timeout_s=WAIT_S) as operator:
        enable(operator)
        # After a loaded host's stall latched a fault: a stop cancels what the last attempt
        # left queued, then all again from enabled and at rest.
        tolerating_stalls(operator, lambda: orphaned_moves_then_stop(api, telemetry, operator),
                          cleanup=lambda: operator.request("stop"))


def orphaned_moves_then_stop(api: str, telemetry: str, operator: HexactlClient) -> None:
    orphan = zmq.Context.instance().socket(zmq.DEALER)
    orphan.linger = 0
    orphan.connect(api)
    for number in range(600):  # slow moves: planning each takes a while, so many are still queued at the stop
        pose = [100 if number % 2 else -100, 0, 0, 0, 0, 0]
        orphan.send(json.dumps({"v": 1, "id": number, "cmd": "move", "pose": pose, "duration": 20.0}).encode())
    with TelemetrySubscriber(telemetry) as records:  # not through the command queue
        wait_for(lambda: records.receive(WAIT_S)["motion"] == "moving", "the orphaned moves to start")
    orphan.close()
    # Until a stop is answered ok: on a host this busy the loop may take over 0.5 s to
    # give its verdict (loop_timeout), and then nothing says when it was carried out.
    wait_for(lambda: operator.request("stop")["ok"], "a stop answered in time")
    # From the stop on (a status sent after a reply reflects it), the platform brakes
    # and stays at rest: no queued move starts again, for a second of the service's time.
    record = status(operator)
    at_rest = None
    while at_rest is None or record["t"] < at_rest["t"] + 1.0:
        assert record["motion"] in ("stopping", "holding"), record
        if record["motion"] == "holding":
            at_rest = at_rest or record
            assert record["pose_command"] == pytest.approx(at_rest["pose_command"], abs=1e-9)
        time.sleep(0.02)
        record = status(operator)
    assert record["state"] == "enabled" and record["faults"] == []
