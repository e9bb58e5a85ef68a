import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.control import planning
from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, LegLock, PlanningContext, project_locked, track_locked
from hexactl.control.trajectory import KinematicState, preview
from hexactl.kinematics.axes import RelativeMmRad
from hexactl.kinematics.inverse import leg_lengths
from hexactl.kinematics.leg_lock import ProjectionStatus, project_to_locked_leg
from hexactl.kinematics.pose import absolute_from_relative, pose_mm_deg_to_mm_rad
from tests.kinematics.calibrations import measured


def _project(geometry, pose, leg, length, **options):
    return project_to_locked_leg(geometry.legs, pose, leg, length, geometry.characteristic_length_mm, **options)


def _gradient(geometry, pose, leg, h=1e-6):
    """∂l/∂pose by central differences: independent of the analytic gradient under test."""
    steps = np.eye(6) * h
    return np.array([(leg_lengths(geometry.legs, pose + s)[leg - 1] - leg_lengths(geometry.legs, pose - s)[leg - 1]) / (2 * h)
                     for s in steps])


def _distance(geometry, a, b):
    """The projection's metric between two absolute poses, mm."""
    c = geometry.characteristic_length_mm
    return float(np.sqrt(np.sum((np.subtract(a, b)) ** 2 * [1, 1, 1, c * c, c * c, c * c])))


offsets = st.tuples(*[st.floats(-40, 40)] * 3, *[st.floats(-3, 3)] * 3)


@pytest.fixture(scope="module", params=["nominal", "measured"])
def platform(request, geometry):
    """The nominal platform, then a measured one (its joints not all at z = 0)."""
    return geometry if request.param == "nominal" else measured(geometry)


@settings(max_examples=60, deadline=None)
@given(offsets, st.integers(1, 6), st.floats(-30.0, 30.0))
def test_projection_is_the_closest_pose_on_the_constraint(platform, offset, leg, change):
    home = absolute_from_relative(platform.home, [0.0] * 6)
    length = leg_lengths(platform.legs, home)[leg - 1] + change
    pose = absolute_from_relative(platform.home, offset)
    result = _project(platform, pose, leg, length)
    assert result.ok
    assert abs(leg_lengths(platform.legs, result.pose)[leg - 1] - length) < 1e-8
    # Optimality: the weighted step W·(x − x₀) is parallel to the constraint's gradient.
    c = platform.characteristic_length_mm
    weighted_step = (np.array(result.pose) - pose) * [1, 1, 1, c * c, c * c, c * c]
    gradient = _gradient(platform, np.array(result.pose), leg)
    across = weighted_step - gradient * (weighted_step @ gradient) / (gradient @ gradient)
    assert np.linalg.norm(across) <= 1e-5 * max(1.0, np.linalg.norm(weighted_step))
    metric = np.sqrt(np.sum((np.array(result.pose) - pose) ** 2 * [1, 1, 1, c * c, c * c, c * c]))
    assert abs(result.correction - metric) < 1e-9 * max(1.0, metric)


def test_a_pose_on_the_constraint_is_its_own_projection(geometry):
    pose = absolute_from_relative(geometry.home, [10, 20, 5, 1, 2, 3])
    length = leg_lengths(geometry.legs, pose)[3]
    result = _project(geometry, pose, 4, length)
    assert result.ok and result.iterations == 0 and result.correction == 0.0
    assert result.pose == tuple(float(v) for v in pose)


def test_two_iterations_suffice_near_the_surface(geometry):
    pose = absolute_from_relative(geometry.home, [10, 20, 5, 1, 2, 3])
    length = leg_lengths(geometry.legs, pose)[0] + 0.5  # half a millimetre off
    result = _project(geometry, pose, 1, length, max_iterations=2)
    assert result.ok and abs(result.residual_mm) < 1e-9


def test_invalid_inputs_are_reported_not_raised(geometry):
    pose = absolute_from_relative(geometry.home, [0.0] * 6)
    for args in ((pose, 0, 2000.0), (pose, 7, 2000.0), (pose, 1, float("nan")), (pose, 1, -5.0),
                 ([float("nan")] * 6, 1, 2000.0), ([1.0] * 5, 1, 2000.0), ("abcdef", 1, 2000.0)):
        assert _project(geometry, *args).status is ProjectionStatus.INVALID_INPUT
    assert project_to_locked_leg(geometry.legs, pose, 1, 2000.0, 0.0).status is ProjectionStatus.INVALID_INPUT
    assert _project(geometry, pose, 1, 1.0, max_iterations=3).status is ProjectionStatus.MAX_ITERATIONS


@pytest.mark.parametrize("huge", [5e301, -1e200, 1e7])
def test_absurd_goals_are_invalid_input_not_an_exception(geometry, huge):
    home = absolute_from_relative(geometry.home, [0.0] * 6)
    length = leg_lengths(geometry.legs, home)[4]
    pose = list(home)
    pose[0] = huge
    assert _project(geometry, pose, 5, length).status is ProjectionStatus.INVALID_INPUT


def test_a_start_on_the_surface_is_not_taken_for_the_projection(geometry):
    """A warm start is the projection of another pose: it lies on the surface already, yet
    the iteration must move on to this pose's projection."""
    home = absolute_from_relative(geometry.home, [0.0] * 6)
    length = leg_lengths(geometry.legs, home)[1]
    start = _project(geometry, absolute_from_relative(geometry.home, [5, 0, 0, 0, 0, 0]), 2, length)
    pose = absolute_from_relative(geometry.home, [10, 3, -2, 0.2, 0, 0.1])
    cold = _project(geometry, pose, 2, length)
    warm = _project(geometry, pose, 2, length, start=start.pose)
    assert start.ok and cold.ok and warm.ok and warm.iterations >= 1
    assert _distance(geometry, start.pose, cold.pose) > 5.0
    assert _distance(geometry, warm.pose, cold.pose) < 1e-5
    assert abs(warm.residual_mm) <= 1e-9
    for bad in ([float("nan")] * 6, [1.0] * 5, [5e301] * 6):
        assert _project(geometry, pose, 2, length, start=bad).status is ProjectionStatus.INVALID_INPUT


def test_the_loops_tracking_converges_in_its_few_iterations_where_a_cold_start_does_not(geometry):
    """Leg 3 locked in the zero posture, a move to roll −15°, pitch −15°, yaw −30°: the goal
    is 1.5 mm from the constraint, but the straight line to it strays 26 mm away. The
    projection started at each cycle's target needs four iterations there; tracked from
    the cycle before (:func:`track_locked`, what the loop and the planner run) it needs at
    most three, and lands on the closest pose: no farther from the target than the
    projection from the target itself, which stops at the same tolerance on the length."""
    iterations = ControllerConfig().lock_cycle_iterations
    active = ActiveGeometry.of(geometry, "nominal")
    lock = LegLock(3, leg_lengths(geometry.legs, active.absolute_from_relative_mm_rad([0.0] * 6))[2] - geometry.zero_lengths[2])
    goal = np.subtract(project_locked(active, lock, pose_mm_deg_to_mm_rad([0, 0, 0, -15, -15, -30])).pose, active.home)
    targets = np.linspace(0.0, 1.0, 1001)[:, None] * goal  # 2 s at 500 Hz
    assert not all(project_locked(active, lock, target, iterations).ok for target in targets)  # what the loop did
    projected = targets[0]
    for previous, target in zip(targets[:-1], targets[1:]):
        result = track_locked(active, lock, target, previous, projected, iterations)
        assert result.ok, result
        cold = project_locked(active, lock, target)
        assert result.correction <= cold.correction + 1e-6
        assert _distance(geometry, result.pose, cold.pose) < 1e-4
        projected = np.subtract(result.pose, active.home)


@pytest.mark.parametrize("leg, goal_mm_deg", [(3, [0, 0, 0, -15, -15, -30]), (1, [60, 40, 20, 3, -2, 5])])
def test_planning_samples_a_locked_move_as_the_loop_commands_it_bit_for_bit(geometry, leg, goal_mm_deg):
    """Planning keeps the locked leg's constraint prepared for the whole path; the loop
    calls :func:`track_locked` afresh each cycle: the same poses, to the last bit."""
    config = ControllerConfig()
    active = ActiveGeometry.of(geometry, "nominal")
    lock = LegLock(leg, leg_lengths(geometry.legs, active.absolute_from_relative_mm_rad([0.0] * 6))[leg - 1]
                   - geometry.zero_lengths[leg - 1])
    context = PlanningContext(active, config.motion, config.loop.period_s, geometry.limits.leg_velocity_mm_s, lock)
    start = KinematicState.at_rest(RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    goal = RelativeMmRad._make(np.subtract(project_locked(active, lock, pose_mm_deg_to_mm_rad(goal_mm_deg)).pose, active.home))
    trajectory = preview(config.motion, config.loop.period_s, start, goal)
    samples = planning._samples(context, start, trajectory, None)
    targets = [start.position] + [trajectory.at_time(k * config.loop.period_s)[0] for k in range(1, len(samples))]
    commanded = [active.relative_from_absolute_mm_rad(project_locked(active, lock, targets[0]).pose)]
    for previous, target in zip(targets[:-1], targets[1:]):
        result = track_locked(active, lock, target, previous, commanded[-1], config.lock_cycle_iterations)
        commanded.append(active.relative_from_absolute_mm_rad(result.pose))
    assert np.array_equal(samples, np.array(commanded, dtype=float))
