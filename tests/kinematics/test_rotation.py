from __future__ import annotations

from math import cos, radians, sin

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hexactl.kinematics.rotation import (
    euler_from_matrix,
    euler_rates_from_angular_velocity,
    rotation_matrices,
    rotation_matrix,
)

angles = st.floats(-np.pi, np.pi, allow_nan=False)
pitches = st.floats(-1.5, 1.5, allow_nan=False)  # away from ±90°, where roll and yaw merge


@given(angles, pitches, angles)
def test_rotation_matches_scipy_intrinsic_zyx(roll: float, pitch: float, yaw: float) -> None:
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    np.testing.assert_allclose(rotation_matrix(roll, pitch, yaw), expected, atol=1e-14)


def test_element_1_3_is_the_corrected_one_not_the_papers_misprint() -> None:
    roll, pitch, yaw = radians(10.0), radians(20.0), radians(30.0)
    corrected = cos(yaw) * sin(pitch) * cos(roll) + sin(yaw) * sin(roll)
    misprint = cos(yaw) * cos(pitch) * sin(pitch) + sin(yaw) * sin(roll)
    element = rotation_matrix(roll, pitch, yaw)[0, 2]
    assert abs(element - corrected) < 1e-15
    assert abs(element - misprint) > 1e-3


@given(st.lists(st.tuples(angles, pitches, angles), min_size=1, max_size=20))
def test_batch_rotations_equal_single(triples: list[tuple[float, float, float]]) -> None:
    roll, pitch, yaw = (np.array(column) for column in zip(*triples))
    batch = rotation_matrices(roll, pitch, yaw)
    for n, (r, p, y) in enumerate(triples):
        np.testing.assert_array_equal(batch[n], rotation_matrix(r, p, y))


@given(angles, pitches, angles)
def test_euler_from_matrix_inverts_rotation_matrix(roll: float, pitch: float, yaw: float) -> None:
    recovered = euler_from_matrix(rotation_matrix(roll, pitch, yaw))
    np.testing.assert_allclose(rotation_matrix(*recovered), rotation_matrix(roll, pitch, yaw), atol=1e-12)
    assert abs(recovered[1] - pitch) < 1e-9


@given(angles, st.floats(-1.2, 1.2), angles, st.lists(st.floats(-1e-3, 1e-3), min_size=3, max_size=3))
def test_euler_rates_reproduce_a_small_fixed_frame_rotation(roll: float, pitch: float, yaw: float, omega: list[float]) -> None:
    rates = euler_rates_from_angular_velocity(np.array(omega), pitch, yaw)
    stepped = rotation_matrix(roll + rates[0], pitch + rates[1], yaw + rates[2])
    expected = Rotation.from_rotvec(omega).as_matrix() @ rotation_matrix(roll, pitch, yaw)
    np.testing.assert_allclose(stepped, expected, atol=1e-5)  # first order in |ω| = 1e-3


def test_euler_angles_of_a_rotation_rounded_past_pitch_90_degrees() -> None:
    t = rotation_matrix(0.0, np.pi / 2, 0.0)
    t[2, 0] = -np.nextafter(1.0, 2.0)  # -sin(pitch) as a product of rotations can round it (pitch 90°)
    assert euler_from_matrix(t)[1] == np.pi / 2
