import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from hexactl.control.trajectory import KinematicState, MotionLimits, PoseTrajectory, StepResult, preview
from hexactl.kinematics.axes import RelativeMmRad

PERIOD = 0.002
GOAL = RelativeMmRad(600.0, -100.0, 50.0, 0.1, -0.05, 0.2)
REST = KinematicState.at_rest(RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


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
    natural = preview(MotionLimits(), PERIOD, REST, GOAL).duration
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
    planned = preview(limits, PERIOD, REST, GOAL)
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


def test_a_move_refused_from_the_current_state_leaves_the_motion_as_it_was():
    trajectory, twin = PoseTrajectory(MotionLimits(), PERIOD), PoseTrajectory(MotionLimits(), PERIOD)
    for generator in (trajectory, twin):
        generator.move_to((0.0, 0.0, -113.0, 0.0, 0.0, 0.0))
        for _ in range(110):
            generator.update()
    assert not trajectory.move_to((0.0, 180.0, -65.0, 0.0, 0.0, np.radians(16)), 4.0)  # ruckig: -101 from here
    assert trajectory.goal == twin.goal
    result, points = _run(trajectory)
    assert result is StepResult.FINISHED and np.array_equal(points, _run(twin)[1])


def test_preview_refuses_non_finite_input():
    assert preview(MotionLimits(), PERIOD, REST, (float("nan"),) * 6) is None


def test_limits_must_be_positive():
    with pytest.raises(ValidationError):
        MotionLimits(max_velocity=(1, 1, 1, 1, 1, 0))


def test_ruckig_exceptions_become_an_error_result():
    trajectory = PoseTrajectory(MotionLimits(), PERIOD)
    trajectory.move_to([1e300] * 6)
    assert trajectory.update() is StepResult.ERROR and not trajectory.moving
    assert trajectory.state()[0] == (0.0,) * 6
    assert preview(MotionLimits(), PERIOD, REST, (1e300,) * 6) is None


def test_a_finished_move_parks_exactly_on_its_goal():
    """ruckig's last sample misses the goal by ~1e-13; the planner starts a sequence's next
    segment at rest on the goal, so the loop must too, bit for bit."""
    trajectory = PoseTrajectory(MotionLimits(), PERIOD)
    for goal in (GOAL, (123.4, 0.1, -7.7, 0.01, 0.02, -0.03)):
        trajectory.move_to(goal, 1.3)
        result, _ = _run(trajectory)
        assert result is StepResult.FINISHED
        assert trajectory.state() == (tuple(goal), (0.0,) * 6, (0.0,) * 6)


# Per axis, the rest-to-rest distance 2·a³/j² at which ruckig 0.19.4's profile just reaches
# the acceleration limit: 40 mm, 40 mm, 24 mm, 2.4°, 2.4°, 3.6° with the default limits.
DEGENERATE = tuple(2 * a**3 / j**2 for a, j in zip(*MotionLimits().in_mm_rad()[1:]))
typed_poses = st.tuples(*[st.integers(-3000, 3000).map(lambda tenths: tenths / 10)] * 6)  # mm and deg, as typed


@settings(max_examples=100, deadline=None)
@given(start=typed_poses, axis=st.integers(0, 5), sign=st.sampled_from([-1, 1]), others=st.booleans(),
       time_scale=st.sampled_from([1.0, 2.5]))
def test_rest_to_rest_moves_by_ruckigs_degenerate_distance_are_planned_and_run(start, axis, sign, others, time_scale):
    """A move by exactly 2·a³/j² on one axis (e.g. pitch 1.2° → 3.6°) used to be refused
    (planning_failed), and one just beside it could fail in the loop (planner_error)."""
    start = np.where(np.arange(6) < 3, start, np.radians(start))
    goal = start / 2 if others else start.copy()
    goal[axis] = start[axis] + sign * DEGENERATE[axis]
    at_rest = KinematicState.at_rest(RelativeMmRad._make(start))
    planned = preview(MotionLimits(), PERIOD, at_rest, goal, time_scale)
    assert planned is not None
    trajectory = PoseTrajectory(MotionLimits(), PERIOD)
    trajectory.reset(start)
    trajectory.move_to(goal, time_scale)
    assert trajectory.update() is StepResult.WORKING  # the loop calculates here, then only samples
    assert trajectory.state()[0] == pytest.approx(planned.at_time(PERIOD)[0], abs=1e-12)


@pytest.mark.parametrize("goal", [(-10, 0, 0, 0, 0, 0), (-10, 0, 4, 0, 0, 0)])
def test_a_halt_never_ends_beyond_the_goal_of_the_move_it_interrupts(goal) -> None:
    """Halted at every cycle of a slow move: the brake, whose duration the time grid
    rounds up, can travel farther than the move's own stop; then the move goes on to its
    goal (and the trajectory says it is halting)."""
    gave_way = 0
    for cycle in range(1, 800):
        trajectory = PoseTrajectory(MotionLimits(), 0.002)
        trajectory.move_to(RelativeMmRad(*goal), velocity_scale=0.1)
        if any(trajectory.update() is not StepResult.WORKING for _ in range(cycle)):
            break
        start = np.array(trajectory.position)
        trajectory.halt()
        gave_way += trajectory.goal is not None
        assert trajectory.halting
        while trajectory.update() is StepResult.WORKING:
            pass
        travel, room = np.abs(np.array(trajectory.position) - start), np.abs(np.array(goal) - start)
        assert np.all(travel <= room), cycle
    assert gave_way  # the case arose
