import numpy as np
import pytest
from pydantic import ValidationError

from hexactl.control.trajectory import MotionLimits, PoseTrajectory, StepResult, preview

PERIOD = 0.002
GOAL = (600.0, -100.0, 50.0, 0.1, -0.05, 0.2)


def _run(trajectory, limit=100_000):
    positions = []
    for _ in range(limit):
        result = trajectory.update()
        positions.append(trajectory.state()[0])
        if result is not StepResult.WORKING:
            return result, np.array(positions)
    raise AssertionError("did not finish")


def _max_distance_from_line(points, goal):
    goal = np.asarray(goal)
    along = points @ goal / (goal @ goal)
    return float(np.max(np.abs(points - along[:, None] * goal)))


@pytest.mark.parametrize(("time_scale", "velocity_scale"), [(1.0, 1.0), (3.0, 1.0), (1.0, 0.3)])
def test_a_move_from_rest_is_a_straight_line_ending_on_the_grid(time_scale, velocity_scale):
    natural = preview(MotionLimits(), PERIOD, ((0.0,) * 6,) * 3, GOAL).duration
    trajectory = PoseTrajectory(MotionLimits(), PERIOD)
    trajectory.move_to(GOAL, time_scale, velocity_scale)
    result, points = _run(trajectory)
    assert result is StepResult.FINISHED
    assert np.allclose(points[-1], GOAL, atol=1e-9)
    assert _max_distance_from_line(points, GOAL) < 1e-9
    if time_scale != 1.0:
        # Both durations are rounded up to the period; k× the natural one within k periods.
        assert len(points) * PERIOD == pytest.approx(natural * time_scale, abs=time_scale * PERIOD)
    assert trajectory.update() is StepResult.IDLE and not trajectory.moving


def test_limits_are_respected_per_axis():
    limits = MotionLimits()
    trajectory = PoseTrajectory(limits, PERIOD)
    trajectory.move_to(GOAL, velocity_scale=0.5)
    _, points = _run(trajectory)
    velocity = np.abs(np.diff(points, axis=0)) / PERIOD
    assert np.all(velocity <= np.array(limits.in_mm_rad()[0]) * 0.5 * (1 + 1e-9))


def test_halt_brakes_on_the_line_and_the_preview_matches_the_online_run():
    limits = MotionLimits()
    planned = preview(limits, PERIOD, ((0.0,) * 6, (0.0,) * 6, (0.0,) * 6), GOAL)
    trajectory = PoseTrajectory(limits, PERIOD)
    trajectory.move_to(GOAL)
    online = []
    for _ in range(400):
        trajectory.update()
        online.append(trajectory.state()[0])
    expected = [planned.at_time((k + 1) * PERIOD)[0] for k in range(400)]
    assert np.allclose(online, expected, atol=1e-9)
    trajectory.halt()
    assert trajectory.halting
    result, points = _run(trajectory)
    assert result is StepResult.FINISHED and not trajectory.moving
    assert np.allclose(trajectory.state()[1], 0.0, atol=1e-9)
    assert _max_distance_from_line(points, GOAL) < 1e-9


def test_preview_refuses_non_finite_input():
    assert preview(MotionLimits(), PERIOD, ((0.0,) * 6,) * 3, (float("nan"),) * 6) is None


def test_limits_must_be_positive():
    with pytest.raises(ValidationError):
        MotionLimits(max_velocity=(1, 1, 1, 1, 1, 0))


def test_ruckig_exceptions_become_an_error_result():
    trajectory = PoseTrajectory(MotionLimits(), PERIOD)
    trajectory.move_to([1e300] * 6)
    assert trajectory.update() is StepResult.ERROR and not trajectory.moving
    assert trajectory.state()[0] == (0.0,) * 6
    assert preview(MotionLimits(), PERIOD, ((0.0,) * 6,) * 3, (1e300,) * 6) is None
