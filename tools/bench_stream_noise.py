"""How a pose stream's noise reaches the platform: the controller follows streams in
simulated time on ideal in-memory actuators (the control tests' rig), one sample a loop
cycle (500 Hz) with seeded uniform noise on x, and reports what was commanded:

- ``hold``: x 0 ± the noise, 3 s: the commanded x's largest excursion;
- ``boundary``: a ramp to x 605, z -252 mm (leg 1's stroke binds; the envelope is at
  x 610), then ± the noise, 8 s: the largest commanded x, the commanded poses beyond a
  hardware limit (every 4th cycle checked) and the set-point guard's clamps;
- ``sine``: x 10 mm · sin(2π·1 Hz·t), no noise, 3 s: the largest tracking error over the
  last period (what a smoother velocity costs a clean stream), and the wall-clock time of
  the facade's ``stream_target`` per sample (its planning, in the API's process).

With several ``--tree`` checkouts (each one's ``hexactl`` imported instead of this one's,
e.g. a ``git worktree`` of the revision before a change) each runs in a process of its own:

    python3 tools/bench_stream_noise.py
    python3 tools/bench_stream_noise.py --tree /tmp/base --tree .
    python3 tools/bench_stream_noise.py --noise 1 5          # only these noises (± mm)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 500
NOISES_MM = (0.1, 1.0, 2.0, 5.0, 10.0, 30.0)


def measure(noises_mm: list[float]) -> dict:
    """Every case's figures at each of ``noises_mm``, with the hexactl on the path."""
    import numpy as np

    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.control.config import ControllerConfig
    from hexactl.control.local_controller import LocalController
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.kinematics.workspace import assess_pose
    from hexactl.sim.ideal_actuators import IdealActuators

    geometry = load_geometry(ROOT / "config" / "platform.toml")

    def follow(path, noise_mm: float, seconds: float, seed: int = 5):
        now = [1_000_000_000]
        actuators = IdealActuators(sensor_setpoints(geometry.legs, geometry.home.in_radians()), clock_ns=lambda: now[0])
        controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(),
                                               clock_ns=lambda: now[0])
        period = controller.config.loop.period_ns

        def step() -> None:
            now[0] += period
            controller.step(now[0])

        assert controller.enable().ok
        step()
        assert controller.stream_open("bench").ok
        step()
        cycles = int(seconds * RATE_HZ)
        noise = np.random.default_rng(seed).uniform(-noise_mm, noise_mm, cycles)
        commanded, spent = [], []
        for n in range(cycles):
            pose = list(path(n / RATE_HZ))
            pose[0] += noise[n]
            began = time.perf_counter()
            controller.stream_target(pose, n + 1, now[0] / 1e9, now[0])
            spent.append(time.perf_counter() - began)
            step()
            commanded.append(controller.snapshot.pose_command.in_degrees())
        follow.spent_us = np.array(spent) * 1e6  # type: ignore[attr-defined]
        return np.array(commanded), controller.snapshot.clamped_cycles

    figures: dict = {"hold": {}, "boundary": {}}
    for noise in noises_mm:
        held, _ = follow(lambda t: (0, 0, 0, 0, 0, 0), noise, 3.0)
        figures["hold"][noise] = float(np.abs(held[:, 0]).max())
        ramp = lambda t: (605.0 * min(1.0, t / 4), 0, -252.0 * min(1.0, t / 4), 0, 0, 0)  # noqa: E731
        edge, clamps = follow(ramp, noise, 8.0)
        outside = sum(not assess_pose(geometry, pose).ok for pose in edge[::4])
        figures["boundary"][noise] = (float(edge[:, 0].max()), outside, clamps)
    sine = lambda t: (10.0 * math.sin(2 * math.pi * t), 0, 0, 0, 0, 0)  # noqa: E731
    traced, _ = follow(sine, 0.0, 3.0)
    times = np.arange(len(traced)) / RATE_HZ
    last = times >= 2.0
    figures["sine"] = float(np.abs(traced[last, 0] - 10.0 * np.sin(2 * np.pi * times[last])).max())
    figures["target_us"] = [float(np.percentile(follow.spent_us, q)) for q in (50, 99)]  # type: ignore[attr-defined]
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, action="append", help="a checkout to measure (default: this one)")
    parser.add_argument("--noise", type=float, nargs="+", default=list(NOISES_MM), help="the noises, ± mm")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    arguments = parser.parse_args()
    if arguments.child:
        import hexactl

        print(json.dumps({"hexactl": str(Path(hexactl.__file__).resolve().parent),
                          "figures": measure(arguments.noise)}))
        return
    sys.path.insert(0, str(ROOT))  # the parent's only: a child must import its tree's hexactl
    from tools.trees import child_reply

    for tree in arguments.tree or [ROOT]:
        figures = child_reply(tree, __file__, ["--child", "--noise", *map(str, arguments.noise)])["figures"]
        p50, p99 = figures["target_us"]
        print(f"\n{tree}: sine x 10 mm at 1 Hz, largest tracking error {figures['sine']:.3f} mm; the facade's "
              f"stream_target per sample (wall clock, this machine as it is) p50 {p50:.0f} µs, p99 {p99:.0f} µs\n")
        print("| noise ± mm | hold x 0: largest commanded x mm | boundary: largest commanded x mm | poses beyond a "
              "hardware limit | guard clamps |")
        print("| --- | --- | --- | --- | --- |")
        for noise in arguments.noise:
            edge_x, outside, clamps = figures["boundary"][str(noise)]
            print(f"| {noise:g} | {figures['hold'][str(noise)]:.2f} | {edge_x:.2f} | {outside} | {clamps} |")


if __name__ == "__main__":
    main()
