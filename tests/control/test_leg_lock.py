import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.kinematics.leg_lock import ProjectionStatus, project_to_locked_leg
from hexactl.kinematics.inverse import leg_lengths
from hexactl.kinematics.pose import absolute_from_relative


def _project(geometry, pose, leg, length, **options):
    return project_to_locked_leg(geometry.legs, pose, leg, length, geometry.characteristic_length_mm, **options)


def _gradient(geometry, pose, leg, h=1e-6):
    """∂l/∂pose by central differences: independent of the analytic gradient under test."""
    steps = np.eye(6) * h
    return np.array([(leg_lengths(geometry.legs, pose + s)[leg - 1] - leg_lengths(geometry.legs, pose - s)[leg - 1]) / (2 * h)
                     for s in steps])


offsets = st.tuples(*[st.floats(-40, 40)] * 3, *[st.floats(-3, 3)] * 3)


@settings(max_examples=60, deadline=None)
@given(offsets, st.integers(1, 6), st.floats(-30.0, 30.0))
def test_projection_is_the_closest_pose_on_the_constraint(geometry, offset, leg, change):
    home = absolute_from_relative(geometry.home, [0.0] * 6)
    length = leg_lengths(geometry.legs, home)[leg - 1] + change
    pose = absolute_from_relative(geometry.home, offset)
    result = _project(geometry, pose, leg, length)
    assert result.ok
    assert abs(leg_lengths(geometry.legs, result.pose)[leg - 1] - length) < 1e-8
    # Optimality: the weighted step W·(x − x₀) is parallel to the constraint's gradient.
    c = geometry.characteristic_length_mm
    weighted_step = (np.array(result.pose) - pose) * [1, 1, 1, c * c, c * c, c * c]
    gradient = _gradient(geometry, np.array(result.pose), leg)
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
