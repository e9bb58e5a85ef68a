"""Drive a running ``hexactl serve`` from Python, and measure the API's round-trip time.

    hexactl serve &                                   # the built-in simulator
    python tools/api_client_example.py                # enable, move, play, follow telemetry, disable
    python tools/api_client_example.py --bench 1000   # round trips of `status`: p50 / p99 / max

Poses are [x, y, z, roll, pitch, yaw] in mm and degrees relative to the zero posture.
"""

from __future__ import annotations

import argparse
import time

from hexactl.adapters.api.client import HexactlClient, TelemetrySubscriber
from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT
from hexactl.adapters.api.protocol import DEFAULT_TELEMETRY_ENDPOINT


GOAL_TOLERANCE = 0.0005
"""How close (mm or deg, each axis) a motion that ran its course rests on its goal (docs/api.md)."""


def wait_until_at_rest(client: HexactlClient, telemetry: TelemetrySubscriber, goal: list[float]) -> dict:
    """Show the pose from the telemetry until ``status`` says the platform holds still
    with no sequence playing; then, by docs/api.md's rule, whether the motion reached
    ``goal`` (the reply's): still enabled and resting on it, else what cut it short.
    (``status`` rather than telemetry decides: it answers after the command before it was
    accepted, while a conflated subscriber may still hold one record from before that
    command.)"""
    while True:
        record = client.call("status")["status"]
        if record["motion"] == "holding" and record["sequence"] is None:
            print()
            if record["state"] != "enabled":
                raise SystemExit(f"cut short: {record['state']}: {[fault['message'] for fault in record['faults']]}")
            if any(abs(a - b) > GOAL_TOLERANCE for a, b in zip(record["pose_command"], goal)):
                raise SystemExit(f"cut short at {record['pose_command']} (a stop, a pause, another client's motion: "
                                 "hexactl events says which)")
            return record
        print("\r  pose", " ".join(f"{v:8.2f}" for v in telemetry.receive()["pose_measured"] or []), end="", flush=True)


def demo(client: HexactlClient, telemetry: TelemetrySubscriber) -> None:
    client.call("enable")  # ok if it already is
    reply = client.call("move", pose=[0, 0, 50, 0, 0, 5], duration=2.0)
    print(f"moving to {reply['goal']} in {reply['duration']:.2f} s")
    print("measured:", [round(v, 3) for v in wait_until_at_rest(client, telemetry, reply["goal"])["pose_measured"]])

    refused = client.request("validate_pose", pose=[700, 0, 0, 0, 0, 0])
    print("x = 700 mm:", refused["refusal"]["message"])

    sequence = {"name": "square", "waypoints": [
        {"pose": [100, 0, 50, 0, 0, 0], "dwell": 0.5},
        {"pose": [100, 100, 50, 0, 0, 0], "dwell": 0.5},
        {"pose": [0, 100, 50, 0, 0, 0], "dwell": 0.5},
        {"pose": [0, 0, 0, 0, 0, 0], "dwell": 0.5},
    ]}
    reply = client.call("play", sequence=sequence)
    print(f"playing {reply['name']}: {reply['waypoints']} waypoints, {reply['duration']:.1f} s")
    wait_until_at_rest(client, telemetry, sequence["waypoints"][-1]["pose"])  # a sequence ends on its last
    client.call("disable")
    print("done; disabled")


def bench(client: HexactlClient, count: int) -> None:
    """Round trips of ``status`` (which builds a full telemetry record), µs."""
    client.call("status")  # connect first
    samples = []
    for _ in range(count):
        start = time.perf_counter()
        client.call("status")
        samples.append((time.perf_counter() - start) * 1e6)
    samples.sort()
    print(f"{count} status round trips, µs: p50 {samples[count // 2]:.0f}  "
          f"p99 {samples[min(count - 1, count * 99 // 100)]:.0f}  max {samples[-1]:.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--api", default=DEFAULT_API_ENDPOINT)
    parser.add_argument("--telemetry", default=DEFAULT_TELEMETRY_ENDPOINT)
    parser.add_argument("--bench", type=int, metavar="N", help="measure N status round trips instead of the demo")
    arguments = parser.parse_args()
    with HexactlClient(arguments.api) as client:
        if arguments.bench:
            bench(client, arguments.bench)
            return
        with TelemetrySubscriber(arguments.telemetry) as telemetry:
            demo(client, telemetry)


if __name__ == "__main__":
    main()
