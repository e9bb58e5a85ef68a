"""Workspace check: every limit a pose violates, with reasons and margins.

A move is accepted or refused whole, so the check reports all violations at once rather
than the first: leg stroke, joint cone angles, the pose envelope and near-singularity.
A path of many poses is checked as arrays (:func:`check_poses`), a pose's violations built
only where it breaks a limit; a stream, which checks a pose or two per target, asks only
whether one pose is inside (:func:`pose_within_limits`). All apply each limit through the
same predicate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from math import atan2, degrees, radians, sqrt
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.geometry import Geometry, Limits, scaled_conditions
from hexactl.kinematics.inverse import (
    leg_jacobian_rows,
    leg_jacobians_batch,
    leg_vectors_batch,
    lengths_from_readings,
    reading_of_leg_length,
    readings_from_lengths,
)
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS
from hexactl.kinematics.rotation import rotation_elements, rotation_matrices


POSE_BOUND_ROUNDING = 1e-9
"""mm or deg a pose may pass a bound on its coordinates by and count as on it (the
envelope's here, the soft limits' in :mod:`~hexactl.kinematics.soft_limits`): the
trajectory generator's samples of a move to a goal on the bound overshoot it by an ulp or
so (610.0000000000001 for x = 610), which is rounding, not motion. The stroke has no such
allowance: the loop's set-point guard enforces it exactly."""


class ViolationKind(StrEnum):
    STROKE_LOW = "stroke_low"
    STROKE_HIGH = "stroke_high"
    BASE_CONE = "base_cone"
    PLATFORM_CONE = "platform_cone"
    POSE_RANGE = "pose_range"
    SINGULAR = "near_singular"
    SOFT_LIMIT = "soft_limit"  # an operator's bound on an axis of the tool pose in the work frame
    SOFT_TILT = "soft_tilt"  # an operator's bound on the tool's tilt in the work frame


@dataclass(frozen=True, slots=True)
class Violation:
    """One violated limit. ``leg`` is 1–6 for leg limits, ``axis`` names a pose axis."""

    kind: ViolationKind
    value: float
    limit: float
    message: str
    leg: int | None = None
    axis: str | None = None


@dataclass(frozen=True, slots=True)
class PoseAssessment:
    """Everything the limits say about one pose (relative pose in mm/deg).

    Margins are distances to the nearest limit in the limit's unit (mm or deg; for the
    condition number, threshold minus value): negative means violated.
    """

    pose_relative: tuple[float, ...]
    sensor_mm: tuple[float, ...]
    stroke_margin_mm: tuple[float, ...]
    base_cone_deg: tuple[float, ...]
    platform_cone_deg: tuple[float, ...]
    pose_margin: tuple[float, ...]
    jacobian_condition: float
    violations: tuple[Violation, ...]

    @property
    def ok(self) -> bool:
        return not self.violations


def assess_poses(geometry: Geometry, poses_relative: Sequence[Sequence[float]] | NDArray) -> list[PoseAssessment]:
    """Check (N, 6) poses relative to the zero posture (mm, deg) against every limit."""
    checks = check_poses(geometry, poses_relative)
    return [checks.assessment(n) for n in range(len(checks.relative))]


@dataclass(frozen=True, slots=True, eq=False)
class PoseChecks:
    """Every limit applied to (N, 6) poses at once (:func:`check_poses`): the figures as
    arrays, ``broken`` (N, K) whether each pose breaks each of the K limits (per leg, per
    axis; a column stands for one kind and leg or axis, in the order a
    :class:`PoseAssessment` lists its violations) and ``ok`` (N,) whether it breaks none.
    A pose's :class:`PoseAssessment` is built on demand: a long path needs only its
    broken poses'."""

    limits: Limits
    relative: NDArray
    sensor: NDArray
    stroke_margin: NDArray
    base_cone: NDArray
    platform_cone: NDArray
    pose_margin: NDArray
    condition: NDArray
    broken: NDArray
    ok: NDArray

    def assessment(self, n: int) -> PoseAssessment:
        """Pose ``n``'s :class:`PoseAssessment`."""
        return PoseAssessment(
            pose_relative=tuple(self.relative[n].tolist()),
            sensor_mm=tuple(self.sensor[n].tolist()),
            stroke_margin_mm=tuple(self.stroke_margin[n].tolist()),
            base_cone_deg=tuple(self.base_cone[n].tolist()),
            platform_cone_deg=tuple(self.platform_cone[n].tolist()),
            pose_margin=tuple(self.pose_margin[n].tolist()),
            jacobian_condition=float(self.condition[n]),
            violations=() if self.ok[n] else tuple(self.violation(n, column)
                                                   for column in np.flatnonzero(self.broken[n]).tolist()),
        )

    def excess(self) -> NDArray:
        """(N, K): how far each pose is beyond each limit of ``broken``'s columns, in the
        limit's unit (mm, deg, a condition number): positive where broken, NaN where a
        figure is (a broken pose)."""
        limits = self.limits
        low, high = limits.stroke
        legs = np.stack((low - self.sensor, self.sensor - high, self.base_cone - limits.base_cone_deg,
                         self.platform_cone - limits.platform_cone_deg), axis=2).reshape(len(self.relative), _LEG_COLUMNS)
        envelope = np.maximum(np.array(limits.pose_min) - POSE_BOUND_ROUNDING - self.relative,
                              self.relative - np.array(limits.pose_max) - POSE_BOUND_ROUNDING)
        return np.concatenate((legs, envelope, (self.condition - limits.max_jacobian_condition)[:, None]), axis=1)

    def violation(self, n: int, column: int) -> Violation:
        """Pose ``n``'s violation of the limit in column ``column`` of ``broken``."""
        limits = self.limits
        if column < _LEG_COLUMNS:
            leg, check = divmod(column, _CHECKS_PER_LEG)
            if check < 2:
                reading = float(self.sensor[n, leg])
                if check == 0:
                    return Violation(ViolationKind.STROKE_LOW, reading, limits.stroke[0],
                        f"leg {leg + 1} below stroke: {_told_apart(reading, limits.stroke[0], '.3f')} mm < "
                        f"{limits.stroke[0]:g} mm", leg=leg + 1)
                return Violation(ViolationKind.STROKE_HIGH, reading, limits.stroke[1],
                    f"leg {leg + 1} above stroke: {_told_apart(reading, limits.stroke[1], '.3f')} mm > "
                    f"{limits.stroke[1]:g} mm", leg=leg + 1)
            kind, angles, limit, where = ((ViolationKind.BASE_CONE, self.base_cone, limits.base_cone_deg, "base")
                if check == 2 else (ViolationKind.PLATFORM_CONE, self.platform_cone, limits.platform_cone_deg, "platform"))
            angle = float(angles[n, leg])
            return Violation(kind, angle, limit,
                f"leg {leg + 1} {where} joint at {angle:.2f}° exceeds its {limit:g}° cone", leg=leg + 1)
        if column < _LEG_COLUMNS + 6:
            index = column - _LEG_COLUMNS
            axis, unit, low, high = POSE_AXES[index], POSE_UNITS[index], limits.pose_min[index], limits.pose_max[index]
            value = float(self.relative[n, index])
            bound = high if value > high else low
            return Violation(ViolationKind.POSE_RANGE, value, bound,
                f"{axis} {_told_apart(value, bound, 'g')} {unit} outside the pose envelope [{low:g}, {high:g}] {unit} "
                f"(by {abs(value - bound):.3g} {unit})", axis=axis)
        condition = float(self.condition[n])
        return Violation(ViolationKind.SINGULAR, condition, limits.max_jacobian_condition,
            f"near-singular pose: Jacobian condition {condition:.1f} > {limits.max_jacobian_condition:g}")


def _told_apart(value: float, bound: float, form: str) -> str:
    """``value`` written in ``form`` ('g', '.3f'), with more digits where that would read as
    ``bound`` (found from outside: "x 610 mm outside the pose envelope [-610, 610] mm (by
    0.0001 mm)", and "-0.000 mm < 0 mm" for a stroke)."""
    kind, digits = form[-1], int(form[1:-1] or 6)
    text = format(value, form)
    while value != bound and float(text) == float(format(bound, f".{digits}{kind}")) and digits < 17:
        digits += 1
        text = format(value, f".{digits}{kind}")
    return text


_CHECKS_PER_LEG = 4  # PoseChecks.broken's columns per leg: stroke low, stroke high, base cone, platform cone
_LEG_COLUMNS = 6 * _CHECKS_PER_LEG  # then one per pose axis (the envelope), then near-singularity


def check_poses(geometry: Geometry, poses_relative: Sequence[Sequence[float]] | NDArray) -> PoseChecks:
    """Check (N, 6) poses relative to the zero posture (mm, deg) against every limit, as
    arrays: what :func:`assess_poses` finds, without a Python object per pose."""
    relative = np.asarray(poses_relative, dtype=float).reshape(-1, 6)
    absolute = absolute_from_relative(geometry.home, relative)
    limits = geometry.limits
    jacobians, lengths = leg_jacobians_batch(geometry.legs, absolute)
    units = jacobians[..., :3]
    sensor = readings_from_lengths(geometry.legs, lengths)
    stroke_low, stroke_high = limits.stroke

    base_axes, platform_axes, _, _ = _neutral_axes(geometry)
    rotations = rotation_matrices(absolute[:, 3], absolute[:, 4], absolute[:, 5])
    base_cone = _angle_deg(units, base_axes[None])
    units_moving = np.einsum("nji,nkj->nki", rotations, units)  # Tᵀ·u: leg seen from the platform
    platform_cone = _angle_deg(units_moving, platform_axes[None])
    pose_min, pose_max = np.array(limits.pose_min), np.array(limits.pose_max)
    pose_margin = np.minimum(relative - pose_min, pose_max - relative)
    condition = _conditions(geometry, jacobians)

    below = _below_stroke(sensor, limits)
    above = _above_stroke(sensor, limits) & ~below  # one stroke violation per leg: a reading is below or above
    legs = np.stack((below, above, _outside_cone(base_cone, limits.base_cone_deg),
                     _outside_cone(platform_cone, limits.platform_cone_deg)), axis=2).reshape(len(relative), _LEG_COLUMNS)
    broken = np.concatenate((legs, _outside_envelope(relative, pose_min, pose_max),
                             near_singular(condition, limits)[:, None]), axis=1)
    return PoseChecks(limits, relative, sensor, np.minimum(sensor - stroke_low, stroke_high - sensor), base_cone,
                      platform_cone, pose_margin, condition, broken, ~broken.any(axis=1))


def assess_pose(geometry: Geometry, pose_relative: Sequence[float]) -> PoseAssessment:
    """Check one pose relative to the zero posture (mm, deg) against every limit."""
    return assess_poses(geometry, [pose_relative])[0]


def pose_within_limits(geometry: Geometry, pose_relative: Sequence[float]) -> bool:
    """Whether one pose relative to the zero posture (mm, deg) breaks none of the limits
    :func:`assess_poses` checks (its ``ok``), the cheapest first, stopping at the first
    broken. Plain floats, not numpy: a stream checks a pose or two per target, and at one
    pose numpy's per-call overhead costs more than the arithmetic (as in
    :func:`~hexactl.kinematics.inverse.leg_lengths`)."""
    limits = geometry.limits
    if any(_outside_envelope(value, low, high) for value, low, high in zip(pose_relative, limits.pose_min, limits.pose_max)):
        return False
    x, y, z, roll, pitch, yaw = (home + value for home, value in zip(geometry.home, pose_relative))
    absolute = (x, y, z, radians(roll), radians(pitch), radians(yaw))
    rows, lengths = leg_jacobian_rows(geometry.legs, absolute)
    for leg, length in enumerate(lengths):
        reading = reading_of_leg_length(geometry.legs, leg, length)
        if _below_stroke(reading, limits) or _above_stroke(reading, limits):
            return False
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = rotation_elements(*absolute[3:])
    _, _, base_axes, platform_axes = _neutral_axes(geometry)
    for (ux, uy, uz, *_), base_axis, platform_axis in zip(rows, base_axes, platform_axes):
        moving = (r0 * ux + r3 * uy + r6 * uz, r1 * ux + r4 * uy + r7 * uz, r2 * ux + r5 * uy + r8 * uz)  # Tᵀ·u
        if _outside_cone(_angle_between_deg((ux, uy, uz), base_axis), limits.base_cone_deg) \
                or _outside_cone(_angle_between_deg(moving, platform_axis), limits.platform_cone_deg):
            return False
    return not near_singular(_condition(geometry, rows), limits)


def assess_readings(geometry: Geometry, readings: Sequence[Sequence[float]] | NDArray,
                    guess_relative: Sequence[float]) -> list[PoseAssessment | None]:
    """Where the platform is at each row of (N, 6) sensor readings (mm) by ``geometry``,
    checked against every limit: forward kinematics warm-started row by row from
    ``guess_relative`` (relative mm/deg), then :func:`assess_poses`. None for a row with
    no pose (forward kinematics did not converge)."""
    guess = absolute_from_relative(geometry.home, guess_relative)
    poses: list[NDArray | None] = []
    for row in np.asarray(readings, dtype=float).reshape(-1, 6):
        result = forward_kinematics(geometry.legs, lengths_from_readings(geometry.legs, row).tolist(), guess)
        poses.append(np.array(result.pose) if result.ok else None)
        guess = result.pose if result.ok else guess
    found = [pose for pose in poses if pose is not None]
    assessed = iter(assess_poses(geometry, relative_from_absolute(geometry.home, np.array(found))) if found else ())
    return [next(assessed) if pose is not None else None for pose in poses]


def jacobian_condition(geometry: Geometry, pose_absolute: Sequence[float]) -> float:
    """Condition number of the twist Jacobian with rotations scaled to lengths.

    The rotation columns (mm/rad) are divided by the mean platform-joint radius so that
    both halves are dimensionless; ``inf`` for a singular pose.
    """
    return _condition(geometry, leg_jacobian_rows(geometry.legs, pose_absolute)[0])


def near_singular(condition: float | NDArray, limits: Limits) -> bool | NDArray:
    """Whether a Jacobian condition number, or each of an array of them, is beyond the
    limits' near-singularity threshold (a NaN condition is)."""
    return (condition != condition) | (condition > limits.max_jacobian_condition)


# Each limit's rule, in one place for the full assessment and the yes/no check. Written
# with comparisons and | so that they apply to plain floats (a bool) and to arrays (of
# bools) alike; x != x is NaN, which counts as outside.
def _below_stroke(reading_mm: float | NDArray, limits: Limits) -> bool | NDArray:
    return reading_mm < limits.stroke[0]


def _above_stroke(reading_mm: float | NDArray, limits: Limits) -> bool | NDArray:
    return reading_mm > limits.stroke[1]


def _outside_cone(angle_deg: float | NDArray, limit_deg: float) -> bool | NDArray:
    return angle_deg > limit_deg


def _outside_envelope(value: float | NDArray, low: float | NDArray, high: float | NDArray) -> bool | NDArray:
    return (value != value) | (value < low - POSE_BOUND_ROUNDING) | (value > high + POSE_BOUND_ROUNDING)


def _condition(geometry: Geometry, jacobian_rows: Sequence[Sequence[float]]) -> float:
    """:func:`jacobian_condition` of the twist Jacobian's rows."""
    return float(_conditions(geometry, np.array(jacobian_rows)[None])[0])


def _conditions(geometry: Geometry, jacobians: NDArray) -> NDArray:
    """:func:`jacobian_condition` of (N, 6, 6) twist Jacobians → (N,): one batched SVD."""
    return scaled_conditions(jacobians, geometry.characteristic_length_mm)


def _angle_between_deg(a: Sequence[float], b: Sequence[float]) -> float:
    """:func:`_angle_deg` of two plain-float unit vectors."""
    ax, ay, az = a
    bx, by, bz = b
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    return degrees(atan2(sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz))


def _angle_deg(a: NDArray, b: NDArray) -> NDArray:
    """Angle between unit vectors along the last axis, deg; atan2 keeps it exact near 0°."""
    a, b = np.broadcast_arrays(a, b)
    # The cross product written out: np.cross's axis handling costs more than the
    # arithmetic on a few vectors (a stream checks one pose per target).
    cross = np.stack((a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), axis=-1)
    return np.degrees(np.arctan2(np.sqrt(np.einsum("...i,...i->...", cross, cross)), np.einsum("...i,...i->...", a, b)))


class _NeutralAxes(NamedTuple):
    """Each joint's neutral axis: the leg direction in the zero posture, (6, 3) in the
    fixed (base joints) and the moving frame (platform joints), and as plain floats."""

    base: NDArray
    platform: NDArray
    base_rows: tuple[tuple[float, ...], ...]
    platform_rows: tuple[tuple[float, ...], ...]


_NEUTRAL_AXES: dict[int, tuple[Geometry, _NeutralAxes]] = {}
_NEUTRAL_AXES_KEPT = 8


def _neutral_axes(geometry: Geometry) -> _NeutralAxes:
    """The joints' neutral axes of ``geometry``, kept for the last few geometries: the same
    one is checked pose after pose."""
    cached = _NEUTRAL_AXES.get(id(geometry))
    if cached is not None and cached[0] is geometry:
        return cached[1]
    axes = _neutral_axes_of(geometry)
    if len(_NEUTRAL_AXES) >= _NEUTRAL_AXES_KEPT:
        _NEUTRAL_AXES.pop(next(iter(_NEUTRAL_AXES)))
    _NEUTRAL_AXES[id(geometry)] = (geometry, axes)
    return axes


def _neutral_axes_of(geometry: Geometry) -> _NeutralAxes:
    home = absolute_from_relative(geometry.home, np.zeros((1, 6)))
    vectors = leg_vectors_batch(geometry.legs, home)[0]
    units = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    rotation = rotation_matrices(home[:, 3], home[:, 4], home[:, 5])[0]
    moving = units @ rotation
    return _NeutralAxes(units, moving, tuple(map(tuple, units.tolist())), tuple(map(tuple, moving.tolist())))
