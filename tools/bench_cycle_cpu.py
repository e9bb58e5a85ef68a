"""CPU time of one control-loop cycle, stepped by hand: a measure the host's load does not
change (``tools/bench_loop.py`` measures the running thread's wall-clock compute, which a
busy host or the planning thread's share of the GIL inflates).

The controller runs on ideal in-memory actuators in simulated time, as the control
tests' rig does; each scenario plays a tour of moves (``lock``: with leg 1 locked; ``frames``:
in the work frame, turning about a pivot point 300 mm above the platform; ``disabled``:
none, the controller disabled) and
``time.thread_time_ns`` is summed around each ``step`` only, so planning, which runs in the
caller's thread, is not counted. Each round steps ``--cycles`` cycles; the minimum over
the rounds is the figure (the least disturbed one), the median beside it. On a shared
virtual machine even CPU time varies by tens of per cent from run to run; ``--calls``
counts the Python function calls per cycle instead (cProfile around each step), which
does not vary at all.

    python3 tools/bench_cycle_cpu.py --rounds 8 --cycles 5000
    python3 tools/bench_cycle_cpu.py --calls --cycles 2000
"""

from __future__ import annotations

import argparse
import cProfile
import itertools
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.control.config import ControllerConfig  # noqa: E402
from hexactl.control.frames import Frame, OperatorFrames  # noqa: E402
from hexactl.control.local_controller import LocalController  # noqa: E402
from hexactl.control.sequences import MotionSequence  # noqa: E402
from hexactl.control.waves import WaveSpec  # noqa: E402
from hexactl.kinematics.inverse import sensor_setpoints  # noqa: E402
from hexactl.sim.ideal_actuators import IdealActuators  # noqa: E402

TOURS = {
    "move": [(300, 0, 0, 0, 0, 0), (-300, 200, 100, 0, 5, 10), (0, -300, -150, 5, -5, -20), (0, 0, 0, 0, 0, 0)],
    "lock": [(30, 0, 0, 0, 0, 0), (0, 30, 0, 0, 0, 2), (-30, 0, 0, 0, 0, -2), (0, 0, 0, 0, 0, 0)],
    "frames": [(0, 0, 0, 10, 0, 0), (50, 0, 0, 0, -10, 5), (0, 50, -20, 5, 5, -10), (0, 0, 0, 0, 0, 0)],
    "turns": [(0, 0, 0, 10, 0, 0), (50, 0, 0, 0, -10, 5), (0, 50, -20, 5, 5, -10), (0, 0, 0, 0, 0, 0)],
    "recording": [(0, 0, 0, 10, 0, 0), (50, 0, 0, 0, -10, 5), (0, 50, -20, 5, 5, -10), (0, 0, 0, 0, 0, 0)],
}
"""``frames`` and ``turns``: the same poses one move after another, in the work frame about
a pivot and in the zero frame: the difference is what the frames cost. ``recording``: the
``turns`` moves with the data recorder capturing every cycle (its rows taken between the
steps, as the loop's exchange does in its slack): the difference is what recording costs."""
WAVES = {
    "wave": WaveSpec(frequency_hz=1.0, cycles=4, axes={"z": {"amplitude": 3.0}, "roll": {"amplitude": 0.3, "phase_deg": 45}}),
    "wave_tool": WaveSpec(frame=Frame.TOOL, frequency_hz=0.8, cycles=4, axes={"roll": {"amplitude": 0.5}}),
}
"""Waves played one after the other (issue 12): ``wave`` on z and roll in the zero frame,
beside ``turns``' moves; ``wave_tool`` a roll about the pivot of :data:`PIVOT`, beside ``frames``."""
DISABLED = "disabled"
"""The scenario without motion: a disabled controller, which follows the measured pose."""
PIVOT = OperatorFrames(work=(0, 0, 300, 0, 0, 0), tool=(0, 0, 300, 0, 0, 0))
"""The ``frames`` scenario's: a tool point 300 mm above the platform, the work frame on it."""

STREAMS = {"stream": (10.0, 0.5)}
"""A pose stream (issue 15): a 1 Hz sine, x 10 mm and roll 0.5°, one target each cycle,
handed over before the step (the receiver's planning, in the caller's thread, is not
counted), so that every step recalculates the generator's plan to pass a new target."""



class _Clock:
    def __init__(self) -> None:
        self.now_ns = 1_000_000_000

    def __call__(self) -> int:
        return self.now_ns


def per_cycle(scenario: str, cycles: int, config_path: Path, profile: cProfile.Profile | None = None) -> float:
    """Mean CPU time of ``cycles`` steps of ``scenario``, µs (the tour replayed as needed);
    with ``profile``, the steps also run under it (and the time is the profiler's too)."""
    geometry = load_geometry(config_path)
    clock = _Clock()
    actuators = IdealActuators(sensor_setpoints(geometry.legs, geometry.home.in_radians()), clock_ns=clock)
    controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(), clock_ns=clock)
    period_ns = controller.config.loop.period_ns
    tour = MotionSequence(name=f"bench_{scenario}", waypoints=[{"pose": pose} for pose in TOURS.get(scenario, TOURS["move"])])

    def step() -> int:
        clock.now_ns += period_ns
        start = time.thread_time_ns()
        if profile is None:
            controller.step(clock.now_ns)
        else:
            profile.runcall(controller.step, clock.now_ns)
        return time.thread_time_ns() - start

    if scenario != DISABLED:
        _expect(controller.enable())
    for _ in range(2):
        step()
    if scenario == "lock":
        _expect(controller.leg_lock(1))
        step()
    frame = Frame.WORK if scenario in ("frames", "wave_tool") else Frame.ZERO
    if frame is Frame.WORK:
        _expect(controller.set_frames(PIVOT))
    if scenario == "recording":
        _expect(controller.record(1, "bench", 1, 1 << 40))
    if scenario in STREAMS:
        _expect(controller.stream_open("bench", timeout_s=10.0))
        step()
    goals = itertools.cycle(TOURS.get(scenario, ()))
    spent_ns = 0
    for n in range(cycles):
        if scenario in STREAMS:
            amplitude_mm, amplitude_deg = STREAMS[scenario]
            phase = math.sin(2 * math.pi * n * period_ns / 1e9)
            controller.stream_target((amplitude_mm * phase, 0, 0, amplitude_deg * phase, 0, 0), n + 1,
                                     (clock.now_ns + period_ns) / 1e9, clock.now_ns + period_ns)
        elif scenario in WAVES:
            if controller.snapshot.motion.value == "holding":
                _expect(controller.wave(WAVES[scenario]))
        elif scenario in ("frames", "turns", "recording"):  # moves one after the other: a sequence's waypoints are in the zero frame
            if controller.snapshot.motion.value == "holding":
                _expect(controller.move(next(goals), frame=frame))
        elif scenario != DISABLED and controller.snapshot.sequence is None:
            _expect(controller.play(tour))
        spent_ns += step()
        controller.take_recorded()  # outside the step: the exchange's work, in the loop's slack
    return spent_ns / cycles / 1e3


def calls_profiled(profile: cProfile.Profile) -> int:
    """Python calls ``profile`` saw, summed over its entries, one per code object. Not
    ``pstats``' total: it keys them by (file, line, name), under which every dataclass's
    generated ``__init__`` is ("<string>", 2, "__init__"), and keeps one of the colliding
    entries, which one depending on where the code objects lie in memory."""
    return sum(entry.callcount for entry in profile.getstats())


def _expect(result) -> None:
    if not result.ok:
        raise SystemExit(f"benchmark set-up failed: {result.error}: {result.message}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    scenarios = sorted([*TOURS, *WAVES, *STREAMS, DISABLED])
    parser.add_argument("--scenario", choices=scenarios, nargs="+", default=scenarios)
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--cycles", type=int, default=5000, help="cycles per round")
    parser.add_argument("--calls", action="store_true", help="count Python calls per cycle instead (one round)")
    parser.add_argument("--geometry", type=Path, default=Path(__file__).resolve().parents[1] / "config" / "platform.toml")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.cycles < 1:
        parser.error("--rounds and --cycles must be at least 1")
    for scenario in args.scenario:
        if args.calls:
            profile = cProfile.Profile()
            per_cycle(scenario, args.cycles, args.geometry, profile)
            calls = calls_profiled(profile)
            print(f"{scenario}: {calls / args.cycles:.1f} Python calls per cycle ({args.cycles} cycles)")
            continue
        figures = [per_cycle(scenario, args.cycles, args.geometry) for _ in range(args.rounds)]
        print(f"{scenario}: CPU per cycle min {min(figures):.1f} µs, median {statistics.median(figures):.1f} µs "
              f"({args.rounds} rounds of {args.cycles} cycles)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
