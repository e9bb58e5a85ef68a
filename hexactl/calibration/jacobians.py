"""Derivatives the calibration needs beyond the core's twist Jacobian.

- leg lengths against the pose in its own coordinates (x, y, z mm; roll, pitch, yaw rad),
  for projections onto a locked leg and for propagating parameter errors to pose errors;
- the covariance of a pose fitted to noisy feature points, which sets how well one
  measured posture pins down a leg length.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import cos, sin

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.inverse import LegModel, twist_jacobian


def angular_velocity_matrix(pitch: float, yaw: float) -> NDArray[np.float64]:
    """E with ω = E·(roll̇, pitcḣ, yaẇ) for T = Rz(yaw)·Ry(pitch)·Rx(roll) (ω in the fixed frame).

    The inverse of :func:`hexactl.kinematics.rotation.euler_rates_from_angular_velocity`;
    its columns are Rz·Ry·ex, Rz·ey and ez.
    """
    cp, sp, cy, sy = cos(pitch), sin(pitch), cos(yaw), sin(yaw)
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])


def length_pose_jacobian(legs: LegModel, pose: Sequence[float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(J, lengths): J (6, 6) = ∂ leg length / ∂ (x, y, z, roll, pitch, yaw), mm/mm and mm/rad.

    ``pose`` is absolute (mm, rad). Built from the core twist Jacobian by the chain rule.
    """
    twist, lengths = twist_jacobian(legs, pose)
    jacobian = twist.copy()
    jacobian[:, 3:] = twist[:, 3:] @ angular_velocity_matrix(pose[4], pose[5])
    return jacobian, lengths


def point_twist_jacobians(points_fixed_mm: NDArray) -> NDArray[np.float64]:
    """∂ point / ∂ twist for points T·p_k already rotated into the fixed frame.

    ``points_fixed_mm`` (..., K, 3) → (..., K, 3, 6): a twist (δR mm, δθ rad, fixed frame)
    moves the point by δR + δθ × (T·p_k), i.e. [I, −[T·p_k]×].
    """
    q = np.asarray(points_fixed_mm, dtype=float)
    out = np.zeros(q.shape[:-1] + (3, 6))
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = 1.0
    out[..., 0, 4], out[..., 0, 5] = q[..., 2], -q[..., 1]
    out[..., 1, 3], out[..., 1, 5] = -q[..., 2], q[..., 0]
    out[..., 2, 3], out[..., 2, 4] = q[..., 1], -q[..., 0]
    return out


def point_fit_twist_covariance(rotations: NDArray, feature_points_mm: NDArray, point_sigma_mm: float) -> NDArray[np.float64]:
    """Covariance (N, 6, 6) of a pose fitted to K feature points with isotropic noise σ.

    In twist coordinates (mm, rad; fixed frame): σ²·(Σ_k A_kᵀA_k)⁻¹ with A_k =
    [I, −[T·p_k]×]. ``rotations`` (N, 3, 3), ``feature_points_mm`` (K, 3) moving frame.
    """
    rotated = np.einsum("nij,kj->nki", np.asarray(rotations, dtype=float), np.asarray(feature_points_mm, dtype=float))
    a = point_twist_jacobians(rotated)
    information = np.einsum("nkri,nkrj->nij", a, a) / point_sigma_mm**2
    return np.linalg.inv(information)
