"""What a halt costs the loop in the cycle it comes (pytest-benchmark): a ``stop``, a jog's
release or lapse brakes through :meth:`PoseTrajectory.halt`, which now also previews where
the brake would come to rest (a halt never ends beyond the goal of the move under way).
Run ``python -m pytest tests/control/test_halt_benchmark.py --benchmark-enable``; figures in
BENCHMARKS.md. Without ``--benchmark-enable`` it runs once, as a test that the halt brakes."""

from __future__ import annotations

import pytest

from hexactl.control.trajectory import MotionLimits, PoseTrajectory
from hexactl.kinematics.axes import RelativeMmRad

PERIOD_S = 0.002


@pytest.mark.parametrize("cycles", [100, 400, 700])
def test_halt_in_the_middle_of_a_move(benchmark, cycles: int) -> None:
    """A 108 mm move at a tenth of the motion limits, halted ``cycles`` cycles in."""

    def moving() -> tuple[tuple[PoseTrajectory], dict]:
        trajectory = PoseTrajectory(MotionLimits(), PERIOD_S)
        trajectory.move_to(RelativeMmRad(-100, 0, 40, 0, 0, 0), velocity_scale=0.1)
        for _ in range(cycles):
            trajectory.update()
        return (trajectory,), {}

    halted = []
    benchmark.pedantic(lambda trajectory: halted.append(trajectory.halt() or trajectory), setup=moving,
                       rounds=200 if benchmark.enabled else 1)
    assert all(trajectory.halting and trajectory.goal is None for trajectory in halted)  # mid-move: a plain brake
