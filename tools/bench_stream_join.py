"""How a pose stream that starts away from the platform is joined: when its samples come
within ``JOIN_DISTANCE`` of the platform, and how fast the platform went until then, in
simulated time (the loop stepped by hand on ideal actuators, as the control tests' rig
does): the figures do not depend on the host's load.

    python3 tools/bench_stream_join.py
    python3 tools/bench_stream_join.py --tree /tmp/before   # a git worktree of another commit
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

CASES: dict[str, tuple[tuple[float, ...], Callable[[float], tuple[float, ...]], int]] = {
    "yaw 10 deg/s from 8 deg off, running away": ((0.0,) * 6, lambda t: (0, 0, 0, 0, 0, 8 + 10 * t), 5),
    "x 250 mm/s from 100 mm off for 1.6 s, running away": (
        (0.0,) * 6, lambda t: (100 + 250 * min(t, 1.6), 0, 0, 0, 0, 0), 0),
    "x +300 mm/s from x 0 for 1.8 s, the platform at x 600: coming towards it": (
        (600.0, 0, 0, 0, 0, 0), lambda t: (300 * min(t, 1.8), 0, 0, 0, 0, 0), 0),
}
"""Name: (the platform's start pose, the stream's pose at t s, both mm and deg, the axis it
moves on). A stream of one target each loop cycle, stamped on the loop's clock."""

SECONDS = 8.0


def joined(tree: Path, start: tuple[float, ...], sample: Callable[[float], tuple[float, ...]],
           axis: int) -> tuple[float | None, float]:
    """When the stream was joined (s; None: not within :data:`SECONDS`) and the fastest the
    platform moved on ``axis`` until then (mm/s or deg/s), with the code of ``tree``
    (first on the import path: :func:`main`)."""
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.control.local_controller import LocalController
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.kinematics.pose import absolute_from_relative
    from hexactl.sim.ideal_actuators import IdealActuators

    geometry = load_geometry(tree / "config" / "platform.toml")
    clock = [1_000_000_000]
    actuators = IdealActuators(sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, start)),
                               clock_ns=lambda: clock[0])
    controller = LocalController.in_thread(actuators, geometry, "nominal", clock_ns=lambda: clock[0])
    period_ns = controller.config.loop.period_ns

    def step() -> None:
        clock[0] += period_ns
        controller.step(clock[0])

    for command in (controller.enable, lambda: controller.stream_open("bench", timeout_s=10.0)):
        for _ in range(10):  # the actuators report their state: enabled, then the stream opens
            step()
        if not (result := command()).ok:
            raise SystemExit(f"bench_stream_join: {result.message}")
    step()
    rate_hz = 1e9 / period_ns
    fastest, last = 0.0, controller.snapshot.pose_command
    for n in range(int(SECONDS * rate_hz)):
        result = controller.stream_target(sample(n / rate_hz), n + 1, clock[0] / 1e9, clock[0])
        step()
        now = controller.snapshot.pose_command
        fastest = max(fastest, abs(now[axis] - last[axis]) * rate_hz)
        last = now
        if result.joining is None:
            break
    else:
        n = None
    return None if n is None else n / rate_hz, math.degrees(fastest) if axis >= 3 else fastest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parents[1],
                        help="the checkout whose code runs (default: this one)")
    arguments = parser.parse_args()
    sys.path.insert(0, str(arguments.tree.resolve()))
    for name, (start, sample, axis) in CASES.items():
        when, fastest = joined(arguments.tree.resolve(), start, sample, axis)
        print(f"{name}: joined {'not within %g s' % SECONDS if when is None else f'after {when:.2f} s'}, "
              f"at most {fastest:.0f} {'deg/s' if axis >= 3 else 'mm/s'} until then")


if __name__ == "__main__":
    main()
