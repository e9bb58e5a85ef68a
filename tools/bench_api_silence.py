"""What a frozen API process costs: ``hexactl serve`` (the built-in simulator) moves the
platform along x; its API process is stopped (SIGSTOP) mid-move, then continued once the
service has logged the silence. Per run: the silence the loop measured when it braked
(``supervision.command_silence_s`` plus up to a heartbeat interval), the wall time from
the SIGSTOP to the service's log line, how far the platform went after the SIGSTOP, and,
the anchor, how far the move had still to go (what it would have run unattended before
the loop watched its API):

    python3 tools/bench_api_silence.py --runs 5
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hexactl.adapters.api.client import CommandError, HexactlClient  # noqa: E402
from tools.serving import serve, spawned_children, wait_for_tool as wait_for  # noqa: E402

SERVICE_SAYS = "nothing from the API process for"
LOOP_SAYS = re.compile(r"loop command_link_silent: nothing from the API for (\d+\.\d) s")


def status(client: HexactlClient) -> dict[str, Any]:
    return client.call("status")["status"]


def send(client: HexactlClient, command: str, **fields: Any) -> None:
    """``command``, carried out even if a loaded host makes the loop's verdict late."""
    try:
        client.call(command, **fields)
    except CommandError as error:
        if error.code != "loop_timeout":
            raise


def one_run(served: Any, client: HexactlClient, goal_x_mm: float, duration_s: float, lead_s: float) -> dict[str, float]:
    """One move toward ``goal_x_mm`` frozen ``lead_s`` into it."""
    said_before = served.log.count(SERVICE_SAYS)
    send(client, "move", pose=[goal_x_mm, 0, 0, 0, 0, 0], duration=duration_s)
    wait_for(lambda: status(client)["motion"] == "moving", "the move under way")
    time.sleep(lead_s)
    at_freeze = status(client)["pose_command"][0]
    [api_process] = spawned_children(served.process.pid)
    stopped = time.monotonic()
    os.kill(api_process, signal.SIGSTOP)
    try:
        wait_for(lambda: served.log.count(SERVICE_SAYS) > said_before, "the service's log line")
        logged_s = time.monotonic() - stopped
    finally:
        os.kill(api_process, signal.SIGCONT)
    wait_for(lambda: status(client)["motion"] == "holding", "the platform at rest")
    at_rest = status(client)["pose_command"][0]
    wait_for(lambda: len(LOOP_SAYS.findall(served.log)) > said_before, "the loop's event in the log")
    silence_s = float(LOOP_SAYS.findall(served.log)[said_before])
    return {"silence_s": silence_s, "logged_s": logged_s, "travel_mm": abs(at_rest - at_freeze),
            "remaining_mm": abs(goal_x_mm - at_freeze)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--distance", type=float, default=150.0, help="the moves' goals: ±this on x, mm")
    parser.add_argument("--duration", type=float, default=6.0, help="each move's duration, s")
    parser.add_argument("--lead", type=float, default=1.0, help="the freeze comes this long into the move, s")
    arguments = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as directory, serve(Path(directory)) as served:
        with HexactlClient(served.api, timeout_s=10) as client:
            send(client, "enable")
            wait_for(lambda: status(client)["state"] == "enabled", "enabled")
            for run in range(arguments.runs):
                goal = arguments.distance * (1 if run % 2 == 0 else -1)
                row = one_run(served, client, goal, arguments.duration, arguments.lead)
                rows.append(row)
                print(f"run {run + 1}: braked at {row['silence_s']:.1f} s of silence, logged {row['logged_s']:.2f} s "
                      f"after the freeze; went {row['travel_mm']:.1f} mm after it, of {row['remaining_mm']:.1f} mm "
                      "the move had left", flush=True)
            send(client, "move", pose=[0, 0, 0, 0, 0, 0])
    load = os.getloadavg()[0]
    for key, what in (("silence_s", "silence when the loop braked, s"), ("logged_s", "SIGSTOP → service log line, s"),
                      ("travel_mm", "travel after the freeze, mm"), ("remaining_mm", "left of the move at the freeze, mm")):
        values = [row[key] for row in rows]
        print(f"{what}: median {statistics.median(values):.2f}, max {max(values):.2f}")
    print(f"{len(rows)} runs, load average {load:.2f}")


if __name__ == "__main__":
    main()
