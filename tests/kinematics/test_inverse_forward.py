from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hexactl.kinematics.forward import FkStatus, forward_kinematics, solve_6x6
from hexactl.kinematics.inverse import (
    leg_lengths,
    leg_lengths_batch,
    sensor_setpoints,
    sensor_setpoints_batch,
    twist_jacobian,
)
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute

from .strategies import relative_poses


@given(relative_poses())
def test_scalar_and_batch_ik_agree_and_match_the_definition(platform, pose_rel: list[float]) -> None:
    pose = absolute_from_relative(platform.home, pose_rel)
    scalar = leg_lengths(platform.legs, pose)
    batch = leg_lengths_batch(platform.legs, pose[None, :])[0]
    rotation = Rotation.from_euler("ZYX", pose[[5, 4, 3]]).as_matrix()
    definition = np.linalg.norm(
        np.array(platform.platform_joints) @ rotation.T + pose[:3] - np.array(platform.base_joints), axis=1
    )
    np.testing.assert_allclose(scalar, definition, atol=1e-9, rtol=0)
    np.testing.assert_allclose(batch, definition, atol=1e-9, rtol=0)
    readings = (definition - platform.zero_lengths) / (1.0 + np.array(platform.sensor_scale_errors))
    np.testing.assert_allclose(sensor_setpoints(platform.legs, pose), readings, atol=1e-9, rtol=0)
    np.testing.assert_allclose(sensor_setpoints_batch(platform.legs, pose[None, :])[0], readings, atol=1e-9, rtol=0)


@given(relative_poses(), st.integers(0, 5))
def test_twist_jacobian_predicts_leg_length_changes(platform, pose_rel: list[float], column: int) -> None:
    pose = absolute_from_relative(platform.home, pose_rel)
    jacobian, _ = twist_jacobian(platform.legs, pose)
    step = 1e-4  # mm or rad; a central difference leaves an O(step³) error

    def lengths_after(twist: np.ndarray) -> np.ndarray:
        rotation = Rotation.from_rotvec(twist[3:]) * Rotation.from_euler("ZYX", pose[[5, 4, 3]])
        moved = np.r_[pose[:3] + twist[:3], rotation.as_euler("ZYX")[::-1]]
        return np.array(leg_lengths(platform.legs, moved))

    twist = np.zeros(6)
    twist[column] = step
    central = (lengths_after(twist) - lengths_after(-twist)) / (2 * step)
    np.testing.assert_allclose(central, jacobian[:, column], atol=1e-6)


@settings(max_examples=300)
@given(relative_poses(scale=0.5))
def test_fk_inverts_ik_from_the_zero_posture(platform, pose_rel: list[float]) -> None:
    pose = absolute_from_relative(platform.home, pose_rel)
    zero = absolute_from_relative(platform.home, [0.0] * 6)
    result = forward_kinematics(platform.legs, leg_lengths(platform.legs, pose), zero)
    assert result.status is FkStatus.OK
    assert result.residual_mm <= 1e-9
    np.testing.assert_allclose(relative_from_absolute(platform.home, result.pose), pose_rel, atol=1e-7)


@given(relative_poses(), st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6))
def test_fk_warm_started_near_the_answer_converges_in_few_iterations(platform, pose_rel, offset) -> None:
    pose = absolute_from_relative(platform.home, pose_rel)
    guess = absolute_from_relative(platform.home, np.add(pose_rel, np.multiply(offset, [1, 1, 1, 0.1, 0.1, 0.1])))
    result = forward_kinematics(platform.legs, leg_lengths(platform.legs, pose), guess)
    assert result.ok and result.iterations <= 5
    np.testing.assert_allclose(result.pose, pose, atol=1e-7)  # the tolerance is on leg lengths (1e-9 mm)


@given(relative_poses(scale=0.5), st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6))
def test_fk_converges_as_newton_does_and_counts_its_iterations(platform, pose_rel, offset) -> None:
    # Newton's method converges quadratically: from 2 mm and 0.2° off, three steps reach
    # 1e-9 mm. A wrong step (a Jacobian or Euler-rate error) still converges, in more.
    pose = absolute_from_relative(platform.home, pose_rel)
    guess = absolute_from_relative(platform.home, np.add(pose_rel, np.multiply(offset, [1, 1, 1, 0.1, 0.1, 0.1])))
    lengths = leg_lengths(platform.legs, pose)
    result = forward_kinematics(platform.legs, lengths, guess)
    assert result.ok and result.iterations <= 3
    capped = forward_kinematics(platform.legs, lengths, guess, max_iterations=result.iterations)
    assert capped.ok and (capped.iterations, capped.pose) == (result.iterations, result.pose)
    at_the_answer = forward_kinematics(platform.legs, lengths, result.pose)
    assert at_the_answer.ok and at_the_answer.iterations == 0


def test_fk_reports_invalid_input_instead_of_raising(nominal) -> None:
    home = absolute_from_relative(nominal.home, [0.0] * 6)
    lengths = leg_lengths(nominal.legs, home)
    for bad_lengths, guess in (([float("nan")] + lengths[1:], home), (lengths[:5], home), (lengths, [np.inf] * 6)):
        result = forward_kinematics(nominal.legs, bad_lengths, guess)
        assert result.status is FkStatus.INVALID_INPUT and not result.ok


def test_fk_does_not_claim_success_for_unreachable_lengths(nominal) -> None:
    home = absolute_from_relative(nominal.home, [0.0] * 6)
    # Legs 1 and 2 share a platform-joint pair; no pose makes one 1 m and the other 4 m long.
    lengths = leg_lengths(nominal.legs, home)
    lengths[0], lengths[1] = 1000.0, 4000.0
    result = forward_kinematics(nominal.legs, lengths, home, max_iterations=30)
    assert result.status in (FkStatus.MAX_ITERATIONS, FkStatus.DIVERGED, FkStatus.SINGULAR)
    assert result.residual_mm > 1e-3 or result.status is FkStatus.DIVERGED


@pytest.mark.parametrize(("pitch_deg", "status"), [
    (80.5, FkStatus.OK), (-80.5, FkStatus.OK), (81.5, FkStatus.DIVERGED), (-85.0, FkStatus.DIVERGED),
])
def test_fk_answers_only_inside_the_euler_chart(platform, pitch_deg: float, status: FkStatus) -> None:
    """Beyond ±81° of pitch the roll–pitch–yaw update nears its singularity at 90°: an
    iterate there is divergence (no pose), even where Newton would converge, so that no
    pose is reported in a chart that cannot describe it well."""
    answer = list(absolute_from_relative(platform.home, [0.0] * 6))
    answer[4] = np.radians(pitch_deg)
    guess = [answer[0] + 1.0, *answer[1:]]
    result = forward_kinematics(platform.legs, leg_lengths(platform.legs, answer), guess)
    assert result.status is status
    if status is FkStatus.OK:
        np.testing.assert_allclose(result.pose, answer, atol=1e-9)
    else:
        assert np.isnan(result.pose).all()


def test_fk_honours_its_iteration_cap(nominal) -> None:
    home = absolute_from_relative(nominal.home, [0.0] * 6)
    target = leg_lengths(nominal.legs, absolute_from_relative(nominal.home, [300.0, -200.0, 100.0, 10.0, -10.0, 30.0]))
    result = forward_kinematics(nominal.legs, target, home, max_iterations=1)
    assert result.status is FkStatus.MAX_ITERATIONS and result.iterations == 1


@given(st.lists(st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6), min_size=6, max_size=6),
       st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6))
def test_solve_6x6_matches_numpy_or_reports_singular(matrix, rhs) -> None:
    a = np.array(matrix)
    solution = solve_6x6(matrix, rhs)
    if solution is None:
        assert np.linalg.cond(a) > 1e10
    elif np.linalg.cond(a) < 1e8:
        np.testing.assert_allclose(a @ solution, rhs, atol=1e-6 * max(1.0, np.abs(a).max() * np.abs(solution).max()))
