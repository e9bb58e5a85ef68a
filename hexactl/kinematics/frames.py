"""Rigid transforms between the fixed, work, platform and tool frames.

An operator's pose names where the *tool* frame (fixed to the platform: the object's
point and axes, its origin the pivot point) is in the *work* frame (fixed to the base:
the table, the beam, the part). With ``W`` the work frame in the fixed frame, ``T`` the
tool frame in the platform frame and ``X`` the tool in the work frame, the platform's
absolute pose is ``P = W·X·T⁻¹``, and ``X = W⁻¹·P·T``.

Poses are (x, y, z, roll, pitch, yaw) in mm and radians, orientation Rz·Ry·Rx
(:mod:`hexactl.kinematics.rotation`). A rotation of ``X`` about its own origin turns the
platform about the tool point, which stays where it is in the fixed frame: the pivot.

Plain floats for one pose, not numpy: the loop maps its commanded pose through the
frames every cycle, where numpy's per-call overhead costs more than the arithmetic (as
in :func:`~hexactl.kinematics.rotation.rotation_elements`); numpy for planning's
batches (:func:`platform_poses`, :func:`tools_in_work`).
"""

from __future__ import annotations

from collections.abc import Sequence
from math import asin, atan2
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.axes import AbsoluteMmRad
from hexactl.kinematics.rotation import rotation_elements, rotation_matrices


class Transform(NamedTuple):
    """A rigid transform: ``rotation`` row by row (nine floats) and ``translation`` (mm).
    It maps a point p of the inner frame to ``rotation·p + translation`` in the outer."""

    rotation: tuple[float, ...]
    translation: tuple[float, float, float]


IDENTITY = Transform((1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))


def transform_of(pose_mm_rad: Sequence[float]) -> Transform:
    """The transform of a pose (x, y, z mm; roll, pitch, yaw rad)."""
    x, y, z, roll, pitch, yaw = pose_mm_rad
    return Transform(rotation_elements(roll, pitch, yaw), (float(x), float(y), float(z)))


def pose_of(transform: Transform) -> tuple[float, float, float, float, float, float]:
    """The pose (mm, rad; pitch in [-π/2, π/2]) of a transform: :func:`transform_of`'s inverse
    away from pitch ±90°, where roll and yaw are not separable."""
    r = transform.rotation
    pitch = asin(max(-1.0, min(1.0, -r[6])))
    return (*transform.translation, atan2(r[7], r[8]), pitch, atan2(r[3], r[0]))


def compose(outer: Transform, inner: Transform) -> Transform:
    """``outer·inner``: the inner transform's frame seen through the outer one."""
    # Written out: the loop composes every cycle, and a generator over the nine elements
    # costs three times as much.
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = outer.rotation
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = inner.rotation
    rotation = (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
                a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
                a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)
    return Transform(rotation, apply(outer, inner.translation))


def inverse(transform: Transform) -> Transform:
    """The transform back: its rotation transposed, its translation undone."""
    r = transform.rotation
    rt = (r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8])
    tx, ty, tz = transform.translation
    return Transform(rt, (-(rt[0] * tx + rt[1] * ty + rt[2] * tz), -(rt[3] * tx + rt[4] * ty + rt[5] * tz),
                          -(rt[6] * tx + rt[7] * ty + rt[8] * tz)))


def apply(transform: Transform, point: Sequence[float]) -> tuple[float, float, float]:
    """The point (mm) of the inner frame in the outer frame."""
    r, (tx, ty, tz) = transform.rotation, transform.translation
    px, py, pz = point
    return (r[0] * px + r[1] * py + r[2] * pz + tx, r[3] * px + r[4] * py + r[5] * pz + ty,
            r[6] * px + r[7] * py + r[8] * pz + tz)


class Frames(NamedTuple):
    """The work frame in the fixed frame and the tool frame in the platform frame."""

    work: Transform = IDENTITY
    tool: Transform = IDENTITY

    def platform_pose(self, tool_in_work_mm_rad: Sequence[float]) -> AbsoluteMmRad:
        """The platform's absolute pose that puts the tool at ``tool_in_work_mm_rad``
        (the tool frame's pose in the work frame, mm and rad): ``W·X·T⁻¹``."""
        return AbsoluteMmRad._make(pose_of(compose(compose(self.work, transform_of(tool_in_work_mm_rad)), inverse(self.tool))))

    def tool_in_work(self, platform_mm_rad: Sequence[float]) -> tuple[float, ...]:
        """The tool frame's pose in the work frame (mm, rad) with the platform at
        ``platform_mm_rad`` (absolute, mm and rad): ``W⁻¹·P·T``."""
        return pose_of(compose(compose(inverse(self.work), transform_of(platform_mm_rad)), self.tool))


def platform_poses(frames: Frames, tool_in_work_mm_rad: NDArray) -> NDArray[np.float64]:
    """:meth:`Frames.platform_pose` of (N, 6) poses at once (planning's samples)."""
    return _poses_batch(_matrix(frames.work) @ _matrices(tool_in_work_mm_rad) @ _matrix(inverse(frames.tool)))


def tools_in_work(frames: Frames, platform_mm_rad: NDArray) -> NDArray[np.float64]:
    """:meth:`Frames.tool_in_work` of (N, 6) poses at once."""
    return _poses_batch(_matrix(inverse(frames.work)) @ _matrices(platform_mm_rad) @ _matrix(frames.tool))


def _matrix(transform: Transform) -> NDArray[np.float64]:
    m = np.eye(4)
    m[:3, :3] = np.reshape(transform.rotation, (3, 3))
    m[:3, 3] = transform.translation
    return m


def _matrices(poses_mm_rad: NDArray) -> NDArray[np.float64]:
    poses = np.asarray(poses_mm_rad, dtype=float).reshape(-1, 6)
    m = np.zeros((len(poses), 4, 4))
    m[:, :3, :3] = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    m[:, :3, 3] = poses[:, :3]
    m[:, 3, 3] = 1.0
    return m


def _poses_batch(m: NDArray) -> NDArray[np.float64]:
    pitch = np.arcsin(np.clip(-m[:, 2, 0], -1.0, 1.0))
    return np.column_stack((m[:, :3, 3], np.arctan2(m[:, 2, 1], m[:, 2, 2]), pitch, np.arctan2(m[:, 1, 0], m[:, 0, 0])))
