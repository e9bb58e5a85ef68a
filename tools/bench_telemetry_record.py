#!/usr/bin/env python3
"""What one telemetry record costs the API's process: its size, and the time to build it
from the loop's latest report and encode it (what the publisher does at the telemetry
rate, 50 Hz by default), with the loop's events as a working service has them (a few
moves and stops since the start: more events than a record carries).

    python3 tools/bench_telemetry_record.py                 # 5000 records, least of 5 runs
    python3 tools/bench_telemetry_record.py --records 20000 --json out.json

The controller runs on ideal in-memory actuators, stepped by hand in simulated time: the
figures are the record's alone, not the loop's. Only public functions that every revision
since the API's own process has are used, so the same tool measures before and after a
change to the record (run it from a checkout of each).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.api.telemetry import telemetry_message  # noqa: E402
from hexactl.adapters.api.wire import jsonable  # noqa: E402
from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.control.local_controller import LocalController  # noqa: E402
from hexactl.kinematics.inverse import sensor_setpoints  # noqa: E402
from hexactl.kinematics.pose import absolute_from_relative  # noqa: E402
from hexactl.sim.ideal_actuators import IdealActuators  # noqa: E402

MOVES = 6
"""Moves, each stopped midway, before measuring: with the enable, 13 events or more."""


class SimClock:
    """Monotonic ns, advanced by hand."""

    def __init__(self) -> None:
        self.now_ns = 1_000_000_000

    def __call__(self) -> int:
        return self.now_ns


def busy_controller() -> LocalController:
    """A controller enabled, after :data:`MOVES` moves stopped midway, at rest."""
    geometry = load_geometry(default_config_path())
    clock = SimClock()
    start = sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, (0.0,) * 6))
    controller = LocalController.in_thread(IdealActuators(start, clock_ns=clock), geometry, "nominal", clock_ns=clock)
    period_ns = controller.config.loop.period_ns

    def run(cycles: int) -> None:
        for _ in range(cycles):
            clock.now_ns += period_ns
            controller.step(clock.now_ns)

    run(2)
    assert controller.enable().ok
    run(2)
    for n in range(MOVES):
        assert controller.move([0, 0, 10.0 * (n % 2), 0, 0, 0], duration=1.0).ok
        run(100)
        controller.stop()
        run(500)
    return controller


def measure(controller: LocalController, records: int) -> float:
    """Seconds per record, built and encoded ``records`` times."""
    begin = time.perf_counter()
    for _ in range(records):
        telemetry_message(jsonable(controller.telemetry()))
    return (time.perf_counter() - begin) / records


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=5000, help="records per run (default 5000)")
    parser.add_argument("--runs", type=int, default=5, help="runs; the least is reported (default 5)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    arguments = parser.parse_args()
    controller = busy_controller()
    message = telemetry_message(jsonable(controller.telemetry()))
    runs = [measure(controller, arguments.records) for _ in range(arguments.runs)]
    figures = {"bytes": len(message), "events_in_record": len(json.loads(message.partition(b" ")[2]).get("events", [])),
               "least_us": min(runs) * 1e6, "median_us": statistics.median(runs) * 1e6,
               "records": arguments.records, "runs": arguments.runs}
    print(f"record: {figures['bytes']} bytes, {figures['events_in_record']} events; built and encoded in "
          f"{figures['least_us']:.0f} µs (least of {arguments.runs} runs of {arguments.records}), "
          f"median {figures['median_us']:.0f} µs")
    if arguments.json:
        arguments.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
