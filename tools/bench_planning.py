"""How long planning long motion takes: validating a 600 s two-axis wave near the motion
limits, a sequence of 500 full-speed waypoints (about 580 s of motion), a leg-locked
move of 600 s, a 30 s move asked while another one is under way, and refusing a 200 s
wave that leaves the envelope (its refusal says which amplitude fits).

The controller runs on ideal in-memory actuators in simulated time (the control tests'
rig); ``time.perf_counter`` and ``time.process_time`` around the facade's
``validate_wave``, ``validate_sequence`` and ``validate_pose`` only, which plan in the
caller's thread. Every plan must be accepted, but the last case's refused. Each figure is the least (and the median)
of ``--repeats`` runs, each run in a fresh process; with several ``--tree`` checkouts
(each one's ``hexactl`` imported instead of this one's, e.g. a ``git worktree`` of the
revision before a change) the runs alternate between them, so that other work on the
machine weighs on each alike:

    python3 tools/bench_planning.py --repeats 3
    python3 tools/bench_planning.py --repeats 5 --tree /tmp/base --tree .
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from functools import partial
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

WAVE = {"frequency_hz": 0.5, "cycles": 300, "axes": {"x": {"amplitude": 40.0}, "roll": {"amplitude": 2.5}}}
"""600 s, two axes near the motion limits (peak acceleration x 395 of 500 mm/s², roll 25 of 30 deg/s²)."""

SEQUENCE_POSES, SEQUENCE_WAYPOINTS = ((-55.0, 0.0, 0.0, 0.0, 0.0, 0.0), (55.0, 0.0, 0.0, 0.0, 0.0, 0.0)), 500
"""The sequence alternates between these (relative mm/deg) at full speed: 110 mm a move,
1.16 s each, 500 waypoints about 580 s of motion (a plan may hold 600 s)."""

LOCKED_LEG, LOCKED_GOAL, LOCKED_DURATION_S = 1, (60.0, 40.0, 20.0, 0.0, 0.0, 0.0), 600.0
"""Leg 1 locked, a move to the projection of this pose taking 600 s."""

UNDERWAY_FIRST, UNDERWAY_CYCLES, UNDERWAY_GOAL, UNDERWAY_DURATION_S = (300.0, 0.0, 0.0, 0.0, 0.0, 0.0), 250, \
    (100.0, 0.0, 0.0, 0.0, 0.0, 0.0), 30.0
"""A move to the first pose at speed 0.1, 0.5 s under way (x about 8 mm, moving +x), then
the second pose validated with a duration of 30 s (the outside tester's case)."""

REFUSED_WAVE = {"frequency_hz": 0.01, "cycles": 2, "axes": {"x": {"amplitude": 900.0}}}
"""200 s, out to x 818 mm (ramped in and out), beyond the envelope's 610 mm: refused."""

CASES = ("wave", "sequence", "locked", "underway", "refused")
CASE_NAMES = {"wave": "600 s two-axis wave (x 40 mm, roll 2.5°, 0.5 Hz), validate_wave",
              "sequence": "500-waypoint full-speed sequence (x ±55 mm, 580 s of motion), validate_sequence",
              "locked": "leg 1 locked, 600 s move, validate_pose",
              "underway": "a 30 s move to x 100 mm asked at x 8 mm moving +x, validate_pose",
              "refused": "200 s wave beyond the envelope (x 900 mm, 0.01 Hz), refused, validate_wave"}


def measure(case: str) -> tuple[float, float, float | None]:
    """The planning time of ``case``, s, wall-clock and CPU (the process's), with the
    hexactl on the path, and the planned motion's duration, s (None: refused)."""
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.control.config import ControllerConfig
    from hexactl.control.local_controller import LocalController
    from hexactl.control.sequences import MotionSequence, SequenceWaypoint
    from hexactl.control.waves import WaveSpec
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.sim.ideal_actuators import IdealActuators

    now = [1_000_000_000]
    geometry = load_geometry(ROOT / "config" / "platform.toml")
    actuators = IdealActuators(sensor_setpoints(geometry.legs, geometry.home.in_radians()), clock_ns=lambda: now[0])
    controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(),
                                           clock_ns=lambda: now[0])
    period = controller.config.loop.period_ns

    def run(cycles: int) -> None:
        for _ in range(cycles):
            now[0] += period
            controller.step(now[0])

    assert controller.enable().ok
    run(3)
    if case in ("wave", "refused"):
        call = partial(controller.validate_wave, WaveSpec(**(WAVE if case == "wave" else REFUSED_WAVE)))
    elif case == "sequence":
        waypoints = [SequenceWaypoint(pose=SEQUENCE_POSES[n % 2]) for n in range(SEQUENCE_WAYPOINTS)]
        call = partial(controller.validate_sequence, MotionSequence(name="long", waypoint=waypoints))
    elif case == "locked":
        assert controller.leg_lock(LOCKED_LEG).ok
        run(3)
        call = partial(controller.validate_pose, LOCKED_GOAL, duration=LOCKED_DURATION_S)
    else:
        assert controller.move(UNDERWAY_FIRST, speed=0.1).ok
        run(UNDERWAY_CYCLES)
        call = partial(controller.validate_pose, UNDERWAY_GOAL, duration=UNDERWAY_DURATION_S)
    begin, begin_cpu = time.perf_counter(), time.process_time()
    result = call()
    times = time.perf_counter() - begin, time.process_time() - begin_cpu
    if case == "refused":
        assert result.error == "path_violation", result.message
        return (*times, None)
    assert result.ok, result.message
    return (*times, result.details["duration_s"])


def measure_tree(tree: Path, cases: list[str]) -> dict[str, tuple[float, float, float | None]]:
    """One run of each case in a child process importing ``tree``'s hexactl."""
    sys.path.insert(0, str(ROOT))  # the parent's only: a child must import its tree's hexactl
    from tools.trees import child_reply

    reply = child_reply(tree, __file__, ["--child", "--case", *cases])
    return {case: tuple(times) for case, times in reply["times"].items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--case", nargs="+", choices=CASES, default=list(CASES))
    parser.add_argument("--tree", type=Path, action="append", help="a checkout to measure (default: this one)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.child:
        import hexactl

        print(json.dumps({"hexactl": str(Path(hexactl.__file__).resolve().parent),
                          "times": {case: measure(case) for case in arguments.case}}))
        return
    trees = arguments.tree or [ROOT]
    results: dict[Path, dict[str, list[tuple[float, float, float | None]]]] = {tree: {case: [] for case in arguments.case}
                                                                  for tree in trees}
    load = os.getloadavg()
    for _ in range(arguments.repeats):
        for tree in trees:
            for case, times in measure_tree(tree, arguments.case).items():
                results[tree][case].append(times)
    load_after = os.getloadavg()
    print(f"load average (1, 5, 15 min): {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} before, "
          f"{load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f} after; {arguments.repeats} runs each\n")
    ratio = len(trees) > 1
    header = " | ".join(f"{tree}: wall least (median), CPU least; motion planned" for tree in trees)
    print(f"| case | {header} |" + (f" {trees[0]} ÷ {trees[-1]}, wall least |" if ratio else ""))
    print("| --- |" + " --- |" * (len(trees) + ratio))
    for case in arguments.case:
        cells, least = [], []
        for tree in trees:
            wall, cpu, planned = zip(*results[tree][case])
            least.append(min(wall))
            motion = "refused" if planned[0] is None else f"{planned[0]:.1f} s"
            cells.append(f"{min(wall):.2f} ({statistics.median(wall):.2f}) s, {min(cpu):.2f} s; {motion}")
        if ratio:
            cells.append(f"{least[0] / least[-1]:.1f}×")
        print(f"| {CASE_NAMES[case]} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
