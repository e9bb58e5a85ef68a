"""Inverse kinematics: leg lengths l_i = ‖T·P_mi + R − B_i‖ (paper, equation 1).

Two paths that agree to 1e-9 mm:

- :func:`leg_lengths` for one pose, the control loop's path. It is plain-float Python on
  purpose: at six legs numpy's per-call overhead (array creation, ufunc dispatch) costs
  more than the arithmetic; BENCHMARKS.md has the measurement that chose it.
- :func:`leg_lengths_batch` for N poses at once (sequences, planning, calibration).

Poses are absolute: mm and rad, see :mod:`hexactl.kinematics.pose`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from math import sqrt

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hexactl.kinematics.rotation import rotation_elements, rotation_matrices

LEG_COUNT = 6


@dataclass(frozen=True, slots=True, eq=False)
class LegModel:
    """A platform's structural parameters in the form the kinematics consumes.

    ``base_joints_mm`` (6, 3): B_i in the fixed frame; ``platform_joints_mm`` (6, 3):
    P_mi in the moving frame; ``zero_lengths_mm`` (6,): joint-to-joint length at sensor 0;
    ``sensor_scale_errors`` (6,), dimensionless, default 0: each sensor's gain error, so that
    leg i's length at reading r is ``zero_i + (1 + e_i)·r`` (a ball screw's lead error).
    Arrays are copied and made read-only so a model shared with the control loop can never
    change under it. Equality is identity: compare the :class:`Geometry` it came from.
    """

    base_joints_mm: NDArray[np.float64]
    platform_joints_mm: NDArray[np.float64]
    zero_lengths_mm: NDArray[np.float64]
    sensor_scale_errors: NDArray[np.float64] = field(default_factory=lambda: np.zeros(LEG_COUNT))
    sensor_gains: NDArray[np.float64] = field(init=False, repr=False)  # 1 + e
    # Per-leg (px, py, pz, bx, by, bz, zero, gain) as plain floats for the scalar path
    # (inverse.py and leg_lock.py, every cycle).
    rows: tuple[tuple[float, ...], ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name, shape in (
            ("base_joints_mm", (LEG_COUNT, 3)),
            ("platform_joints_mm", (LEG_COUNT, 3)),
            ("zero_lengths_mm", (LEG_COUNT,)),
            ("sensor_scale_errors", (LEG_COUNT,)),
        ):
            array = np.array(getattr(self, name), dtype=float)
            if array.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        gains = 1.0 + self.sensor_scale_errors
        gains.flags.writeable = False
        object.__setattr__(self, "sensor_gains", gains)
        rows = tuple(
            tuple(float(v) for v in (*p, *b, z, g))
            for p, b, z, g in zip(self.platform_joints_mm, self.base_joints_mm, self.zero_lengths_mm, gains)
        )
        object.__setattr__(self, "rows", rows)


def leg_lengths(model: LegModel, pose: Sequence[float]) -> list[float]:
    """Joint-to-joint length of each leg, mm, for one absolute pose (mm, rad)."""
    x, y, z, roll, pitch, yaw = pose
    r11, r12, r13, r21, r22, r23, r31, r32, r33 = rotation_elements(roll, pitch, yaw)
    lengths = []
    for px, py, pz, bx, by, bz, _, _ in model.rows:
        dx = r11 * px + r12 * py + r13 * pz + x - bx
        dy = r21 * px + r22 * py + r23 * pz + y - by
        dz = r31 * px + r32 * py + r33 * pz + z - bz
        lengths.append(sqrt(dx * dx + dy * dy + dz * dz))
    return lengths


def sensor_setpoints(model: LegModel, pose: Sequence[float]) -> list[float]:
    """Actuator sensor readings, mm, that put the platform at ``pose``."""
    return [reading_of_leg_length(model, leg, length) for leg, length in enumerate(leg_lengths(model, pose))]


def reading_of_leg_length(model: LegModel, leg_index: int, length: float) -> float:
    """Leg ``leg_index``'s (0-based) sensor reading, mm, at joint-to-joint ``length``, mm:
    (length − zero) / gain, the scalar copy of :func:`readings_from_lengths`."""
    row = model.rows[leg_index]
    return (length - row[6]) / row[7]


def leg_length_of_reading(model: LegModel, leg_index: int, reading: float) -> float:
    """Leg ``leg_index``'s (0-based) length, mm, at sensor ``reading``, mm: the scalar copy
    of :func:`lengths_from_readings` for the loop (leg-lock tracking, every cycle)."""
    row = model.rows[leg_index]
    return row[6] + row[7] * reading


# The sensor model, length = zero + gain·reading, lives in these two functions (and in the
# scalar copies above, reading_of_leg_length and leg_length_of_reading, plain floats for the loop).
def lengths_from_readings(model: LegModel, readings: ArrayLike, legs: int | slice = slice(None)) -> NDArray[np.float64]:
    """Joint-to-joint lengths, mm, of sensor readings, mm, shaped (..., 6), or of leg index
    ``legs`` (0-based) alone: ``zero + (1 + e)·reading``."""
    return model.zero_lengths_mm[legs] + model.sensor_gains[legs] * np.asarray(readings, dtype=float)


def readings_from_lengths(model: LegModel, lengths: ArrayLike, legs: int | slice = slice(None)) -> NDArray[np.float64]:
    """Sensor readings, mm, of joint-to-joint lengths, mm (the inverse of :func:`lengths_from_readings`)."""
    return (np.asarray(lengths, dtype=float) - model.zero_lengths_mm[legs]) / model.sensor_gains[legs]


def leg_vectors_batch(model: LegModel, poses: NDArray) -> NDArray[np.float64]:
    """Leg vectors B_iP_i in the fixed frame, mm, for (N, 6) absolute poses → (N, 6, 3)."""
    return _legs_batch(model, poses)[0]


def _legs_batch(model: LegModel, poses: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The leg vectors (N, 6, 3) of (N, 6) absolute poses and the platform joints
    relative to the platform's origin in the fixed frame, T·P_mi (N, 6, 3), mm."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    rotations = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    joints = model.platform_joints_mm
    # Σ_j T_ij·P_kj written out, in einsum's order: its generic loop takes three times as long at (N, 6, 3)
    platform_in_fixed = (rotations[:, None, :, 0] * joints[:, 0, None] + rotations[:, None, :, 1] * joints[:, 1, None]
                         + rotations[:, None, :, 2] * joints[:, 2, None])
    return platform_in_fixed + poses[:, None, :3] - model.base_joints_mm[None, :, :], platform_in_fixed


def leg_lengths_batch(model: LegModel, poses: NDArray) -> NDArray[np.float64]:
    """Leg lengths, mm, for (N, 6) absolute poses (mm, rad) → (N, 6)."""
    vectors = leg_vectors_batch(model, poses)
    return np.sqrt(np.einsum("nki,nki->nk", vectors, vectors))


def sensor_setpoints_batch(model: LegModel, poses: NDArray) -> NDArray[np.float64]:
    """Sensor readings, mm, for (N, 6) absolute poses → (N, 6)."""
    return readings_from_lengths(model, leg_lengths_batch(model, poses))


def leg_jacobian_rows(model: LegModel, pose: Sequence[float]) -> tuple[list[list[float]], list[float]]:
    """Twist Jacobian rows and leg lengths for one absolute pose, as plain floats.

    Row i is [u_i, (T·P_mi) × u_i] with u_i the unit leg vector, so that δl = J·[δR; δθ]
    for a translation δR (mm) and a small rotation δθ (rad, fixed frame). Plain floats for
    the same reason as :func:`leg_lengths`: forward kinematics runs this every cycle.
    """
    x, y, z, roll, pitch, yaw = pose
    r11, r12, r13, r21, r22, r23, r31, r32, r33 = rotation_elements(roll, pitch, yaw)
    rows = []
    lengths = []
    for px, py, pz, bx, by, bz, _, _ in model.rows:
        qx = r11 * px + r12 * py + r13 * pz
        qy = r21 * px + r22 * py + r23 * pz
        qz = r31 * px + r32 * py + r33 * pz
        dx, dy, dz = qx + x - bx, qy + y - by, qz + z - bz
        length = sqrt(dx * dx + dy * dy + dz * dz)
        ux, uy, uz = dx / length, dy / length, dz / length
        rows.append([ux, uy, uz, qy * uz - qz * uy, qz * ux - qx * uz, qx * uy - qy * ux])
        lengths.append(length)
    return rows, lengths


def leg_jacobians_batch(model: LegModel, poses: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`leg_jacobian_rows` of (N, 6) absolute poses (mm, rad) at once: the twist
    Jacobians (N, 6, 6), row i [u_i, (T·P_mi) × u_i], and the leg lengths (N, 6), mm."""
    vectors, joints = _legs_batch(model, poses)
    lengths = np.linalg.norm(vectors, axis=2)
    units = vectors / lengths[..., None]
    (qx, qy, qz), (ux, uy, uz) = np.moveaxis(joints, 2, 0), np.moveaxis(units, 2, 0)
    moments = np.stack((qy * uz - qz * uy, qz * ux - qx * uz, qx * uy - qy * ux), axis=2)
    return np.concatenate((units, moments), axis=2), lengths


def twist_jacobian(model: LegModel, pose: Sequence[float]) -> tuple[NDArray, NDArray]:
    """:func:`leg_jacobian_rows` as arrays: J (6, 6) and the leg lengths (6,), mm."""
    rows, lengths = leg_jacobian_rows(model, pose)
    return np.array(rows), np.array(lengths)
