"""Platform orientation: T = Rz(yaw)·Ry(pitch)·Rx(roll), the paper's equation (2).

The paper prints element (1,3) as cos(yaw)·cos(pitch)·sin(pitch); the correct element,
used here, is cos(yaw)·sin(pitch)·cos(roll) + sin(yaw)·sin(roll). All angles are in
radians; the edges of the program (CLI, API, files) speak degrees.
"""

from __future__ import annotations

from math import asin, atan2, cos, sin

import numpy as np
from numpy.typing import NDArray

Matrix3 = NDArray[np.float64]


def rotation_elements(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """T = Rz(yaw)·Ry(pitch)·Rx(roll) row by row as nine plain floats (angles in rad).

    Plain floats because the control loop's IK, FK and leg-lock projection use it every
    cycle, where numpy's per-call overhead costs more than the arithmetic.
    """
    cr, sr = cos(roll), sin(roll)
    cp, sp = cos(pitch), sin(pitch)
    cy, sy = cos(yaw), sin(yaw)
    return (
        cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
        sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
        -sp, cp * sr, cp * cr,
    )  # fmt: skip


def rotation_matrix(roll: float, pitch: float, yaw: float) -> Matrix3:
    """The 3×3 rotation T = Rz(yaw)·Ry(pitch)·Rx(roll) (angles in rad)."""
    return np.array(rotation_elements(roll, pitch, yaw)).reshape(3, 3)


def rotation_matrices(roll: NDArray, pitch: NDArray, yaw: NDArray) -> NDArray[np.float64]:
    """Vectorised :func:`rotation_matrix`: arrays of N angles (rad) to (N, 3, 3)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    out = np.empty((np.shape(roll)[0], 3, 3))
    out[:, 0, 0] = cy * cp
    out[:, 0, 1] = cy * sp * sr - sy * cr
    out[:, 0, 2] = cy * sp * cr + sy * sr
    out[:, 1, 0] = sy * cp
    out[:, 1, 1] = sy * sp * sr + cy * cr
    out[:, 1, 2] = sy * sp * cr - cy * sr
    out[:, 2, 0] = -sp
    out[:, 2, 1] = cp * sr
    out[:, 2, 2] = cp * cr
    return out


def euler_from_matrix(t: Matrix3) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad of a rotation T = Rz·Ry·Rx; pitch in [-π/2, π/2].

    This is the paper's special-point method (section 3.1) in closed form: the image of
    the moving x axis gives yaw and pitch, the moving z axis's gives roll. At pitch = ±90°
    roll and yaw are not separable; the platform's ±23° pitch stroke stays far from it.
    """
    pitch = asin(max(-1.0, min(1.0, -float(t[2, 0]))))
    roll = atan2(float(t[2, 1]), float(t[2, 2]))
    yaw = atan2(float(t[1, 0]), float(t[0, 0]))
    return roll, pitch, yaw


def euler_rates_from_angular_velocity(
    omega: NDArray, pitch: float, yaw: float
) -> tuple[float, float, float]:
    """Map a small rotation vector ω (fixed frame, rad) to (roll, pitch, yaw) increments.

    For T = Rz·Ry·Rx, ω = ψ̇·ez + θ̇·Rz·ey + φ̇·Rz·Ry·ex; inverted in closed form. Valid
    away from pitch = ±90°.
    """
    wx, wy, wz = float(omega[0]), float(omega[1]), float(omega[2])
    cy, sy = cos(yaw), sin(yaw)
    roll_rate = (wx * cy + wy * sy) / cos(pitch)
    pitch_rate = -wx * sy + wy * cy
    yaw_rate = wz + roll_rate * sin(pitch)
    return roll_rate, pitch_rate, yaw_rate
