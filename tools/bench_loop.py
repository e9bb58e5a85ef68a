#!/usr/bin/env python3
"""Benchmark the control loop thread: wake-up lateness, missed cycles, compute per cycle.

Runs the real :class:`hexactl.control.local_controller.LocalController` thread for ``--seconds`` at
each ``--rate`` against a hardware back-end (``--hardware``; today the in-memory ideal
actuators) while a scenario keeps it busy, then prints the loop statistics.

    python tools/bench_loop.py                       # 500 Hz and 1 kHz, 10 s each, moving
    python tools/bench_loop.py --fifo 80 --cpu 1 --mlock --seconds 30
    python tools/bench_loop.py --scenario hold --json results.json

Scenarios: ``move`` plays moves back and forth through the whole workspace
(trajectory, IK, guard, FK and send every cycle); ``hold`` enables and holds; ``lock``
plays the moves in leg-lock mode (adds the per-cycle projection).

Extending: a back-end is a function in :data:`HARDWARE` returning an
``ActuatorInterface`` (add the CAN link there); another measurement to print side by
side (e.g. cyclictest on the same CPU) is a function in :data:`REFERENCES` returning a
dict of the same keys as :func:`loop_row`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.files.geometry_file import geometry_id, load_geometry  # noqa: E402
from hexactl.control.config import ControllerConfig, LoopConfig  # noqa: E402
from hexactl.control.local_controller import LocalController  # noqa: E402
from hexactl.control.hardware import ActuatorInterface  # noqa: E402
from hexactl.control.realtime import RealtimeConfig  # noqa: E402
from hexactl.control.sequences import MotionSequence  # noqa: E402
from hexactl.kinematics.geometry import Geometry  # noqa: E402
from hexactl.kinematics.inverse import sensor_setpoints  # noqa: E402
from hexactl.sim.ideal_actuators import IdealActuators  # noqa: E402


def ideal_actuators(geometry: Geometry) -> ActuatorInterface:
    """Six in-memory actuators at the zero posture."""
    return IdealActuators(sensor_setpoints(geometry.legs, geometry.home.in_radians()))


HARDWARE: dict[str, Callable[[Geometry], ActuatorInterface]] = {"ideal": ideal_actuators}
REFERENCES: dict[str, Callable[[argparse.Namespace, float], dict]] = {}

_TOUR = MotionSequence(name="bench_tour", waypoints=[
    {"pose": pose} for pose in (
        (300, 0, 0, 0, 0, 0), (-300, 200, 100, 0, 5, 10), (0, -300, -150, 5, -5, -20),
        (100, 100, 100, 5, 5, 5), (0, 0, 0, 0, 0, 0))
])
_LOCK_TOUR = MotionSequence(name="bench_lock_tour", waypoints=[
    {"pose": pose} for pose in ((30, 0, 0, 0, 0, 0), (0, 30, 0, 0, 0, 2), (-30, 0, 0, 0, 0, -2), (0, 0, 0, 0, 0, 0))
])


def run_once(args: argparse.Namespace, rate_hz: float, geometry: Geometry) -> dict:
    """One measurement at ``rate_hz``; returns :func:`loop_row`'s dict."""
    realtime = RealtimeConfig(fifo_priority=args.fifo, cpus=tuple(args.cpu) if args.cpu else None,
                              lock_memory=args.mlock, switch_interval_s=args.switch_us / 1e6)
    config = ControllerConfig(loop=LoopConfig(rate_hz=rate_hz, spin_window_us=args.spin_us, realtime=realtime))
    controller = LocalController.in_thread(HARDWARE[args.hardware](geometry), geometry, geometry_id(geometry), config=config)
    report = controller.start()
    try:
        _expect(controller.enable())
        tour = _TOUR
        if args.scenario == "lock":
            _expect(controller.leg_lock(1))
            tour = _LOCK_TOUR
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            if args.scenario != "hold" and controller.snapshot.sequence is None:
                _expect(controller.play(tour))  # planning runs in this thread, as the API's would
            time.sleep(0.1)
        telemetry = controller.telemetry()
    finally:
        controller.shutdown()
    return loop_row(f"hexactl {args.scenario}", rate_hz, telemetry.loop, report.notes)


def loop_row(name: str, rate_hz: float, stats, notes=()) -> dict:
    return {
        "name": name, "rate_hz": rate_hz, "cycles": stats.cycles, "missed": stats.missed, "skipped": stats.skipped,
        "late_p50_us": stats.lateness_us.p50, "late_p99_us": stats.lateness_us.p99,
        "late_p999_us": stats.lateness_us.p999, "late_max_us": stats.lateness_us.max,
        "compute_p50_us": stats.compute_us.p50, "compute_p99_us": stats.compute_us.p99,
        "compute_max_us": stats.compute_us.max, "gc_runs": stats.gc_runs, "gc_max_us": stats.gc_max_us,
        "guard_clamps": stats.guard_clamps, "notes": list(notes),
    }


def print_table(rows: list[dict]) -> None:
    columns = [("name", "{}"), ("rate_hz", "{:.0f}"), ("cycles", "{}"), ("missed", "{}"), ("skipped", "{}"),
               ("late_p50_us", "{:.1f}"), ("late_p99_us", "{:.1f}"), ("late_p999_us", "{:.1f}"),
               ("late_max_us", "{:.1f}"), ("compute_p50_us", "{:.1f}"), ("compute_p99_us", "{:.1f}"),
               ("compute_max_us", "{:.1f}"), ("gc_runs", "{}"), ("gc_max_us", "{:.1f}"), ("guard_clamps", "{}")]
    cells = [[fmt.format(row[key]) for key, fmt in columns] for row in rows]
    widths = [max(len(key), *(len(c[i]) for c in cells)) for i, (key, _) in enumerate(columns)]
    print("  ".join(key.rjust(w) for (key, _), w in zip(columns, widths)))
    for line in cells:
        print("  ".join(c.rjust(w) for c, w in zip(line, widths)))
    for row in rows:
        for note in row["notes"]:
            print(f"note ({row['name']} {row['rate_hz']:.0f} Hz): {note}")


def _expect(result) -> None:
    if not result.ok:
        raise SystemExit(f"benchmark set-up failed: {result.error}: {result.message}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, nargs="+", default=[500.0, 1000.0], help="loop rates, Hz")
    parser.add_argument("--seconds", type=float, default=10.0, help="duration of each run")
    parser.add_argument("--scenario", choices=("move", "hold", "lock"), default="move")
    parser.add_argument("--hardware", choices=sorted(HARDWARE), default="ideal")
    parser.add_argument("--geometry", default=str(Path(__file__).resolve().parents[1] / "config" / "platform.toml"))
    parser.add_argument("--fifo", type=int, default=None, help="SCHED_FIFO priority of the loop thread")
    parser.add_argument("--cpu", type=int, nargs="+", default=None, help="CPUs for the loop thread")
    parser.add_argument("--caller-fifo", type=int, default=None,
                        help="SCHED_FIFO priority of the calling (planning) thread, below --fifo")
    parser.add_argument("--mlock", action="store_true", help="mlockall the process")
    parser.add_argument("--spin-us", type=float, default=LoopConfig().spin_window_us, help="busy-wait window, µs")
    parser.add_argument("--switch-us", type=float, default=RealtimeConfig().switch_interval_s * 1e6,
                        help="GIL switch interval while running, µs")
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = parser.parse_args(argv)
    geometry = load_geometry(args.geometry)
    if args.caller_fifo is not None:
        # The caller's thread shares the GIL with the loop: preempted while holding it,
        # it stalls the loop (priority inversion). See the report on deployment.
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.caller_fifo))
    rows = []
    for rate in args.rate:
        rows.append(run_once(args, rate, geometry))
        rows += [reference(args, rate) for reference in REFERENCES.values()]
    print_table(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
