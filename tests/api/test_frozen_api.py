"""A frozen API process cannot pass on an E-stop, so the loop does not run on unattended:
``hexactl serve`` with its API process stopped (SIGSTOP) in the middle of a long move
brakes the move to rest on its own once nothing has come from the API for
``supervision.command_silence_s``, says so on its log while the API is still frozen,
and takes commands again once it is back.

The real command in a process of its own, on random loopback ports read from its log.
"""

from __future__ import annotations

from pathlib import Path

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.control.config import SupervisionConfig
from tests.reliability.support import hold_up_api, is_stall
from tools.serving import HANG_S, serve, terminate, wait_until

GOAL_X_MM = 150.0
MOVE_S = 30.0  # slow: still far from its goal when the loop brakes


def status(client: HexactlClient) -> dict:
    return client.call("status")["status"]


def test_a_frozen_api_process_has_the_loop_brake_a_move_on_its_own(tmp_path: Path) -> None:
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=10) as client:
            try:
                client.call("enable")
                client.call("move", pose=[GOAL_X_MM, 0, 0, 0, 0, 0], duration=MOVE_S)
            except CommandError as error:  # a loaded host: the loop's verdict came too late, not a refusal
                assert error.code == "loop_timeout", error
            wait_until(lambda: status(client)["motion"] == "moving", "the move under way", HANG_S,
                       seen=lambda: status(client))
            hold_up_api(served)
            wait_until(lambda: status(client)["motion"] == "holding", "the platform at rest", HANG_S,
                       seen=lambda: status(client))
            record = status(client)
            wait_until(lambda: "heard again" in served.log, "the API heard again", HANG_S, seen=lambda: served.log)
        shutdown = terminate(served)
        assert shutdown.problems() == [], served.log
    log = served.log
    print(log)
    assert f"nothing from the API for {SupervisionConfig().command_silence_s:.1f} s" in log, log
    assert record["pose_command"][0] < GOAL_X_MM - 10.0, record  # the move did not run on to its goal
    if record["state"] == "enabled":
        assert "loop command_link_silent:" in log and "the motion is braked to rest" in log, log
    else:  # a loaded host stalled the simulated actuators meanwhile: they hold where they were
        assert record["faults"] and all(is_stall(fault) for fault in record["faults"]), record
