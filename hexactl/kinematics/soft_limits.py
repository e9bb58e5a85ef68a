"""An operator's workspace inside the hardware's: soft limits.

A box per axis of the tool's pose in the work frame (mm, deg; see
:mod:`hexactl.kinematics.frames`) and a bound on its tilt: the angle between the tool
frame's z axis and the work frame's. They are checked *with* the hardware's limits
(:func:`~hexactl.kinematics.workspace.assess_poses`), never instead of them, so they can
narrow what is allowed and never widen it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from math import acos, cos, degrees, radians

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from hexactl.kinematics.axes import MAX_TILT_DEG, POSE_AXES, POSE_MAGNITUDE_LIMIT, POSE_UNITS, AxisName
from hexactl.kinematics.numbers import Number
from hexactl.kinematics.workspace import POSE_BOUND_ROUNDING, Violation, ViolationKind

Bound = Number | None
"""One axis's soft bound in its unit (mm or deg); None: none on that side."""

Bounds = tuple[Bound, Bound, Bound, Bound, Bound, Bound]
NO_BOUNDS: Bounds = (None,) * 6

_TURNING_AXES = (3, 5)
"""Roll and yaw: they read in [-180°, 180°], ±180° for one orientation (pitch in [-90°, 90°])."""

_HALF_TURN_READ = 180.0 - POSE_BOUND_ROUNDING
"""An angle read this far from 0 or farther is at ±180°."""

_LIMITED = "the tool's {} in the work frame"
"""What a soft limit bounds, as a refusal names it: an axis of the tool in the work frame, not
the axis the operator moved (found from outside: y=40 about a work frame turned 90° was
refused as "x 40.000 mm above the soft limit 30 mm", read as the wrong axis)."""


class SoftLimits(BaseModel):
    """``lower``/``upper``: per axis of the tool's pose in the work frame, mm and deg
    (None, for an axis or all: no soft limit on that side); ``max_tilt_deg``: bound on
    the tilt (None: none).

    :raises pydantic.ValidationError: a bound not finite, ``lower`` not below ``upper``
        on every axis, an angle's bound beyond where it reads (a window across ±180°), or a
        tilt bound outside (0, 90] degrees
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    lower: Bounds = Field(default=NO_BOUNDS, description="lower bound per axis (x, y, z mm; roll, pitch, yaw deg) or null")
    upper: Bounds = Field(default=NO_BOUNDS, description="upper bound per axis (x, y, z mm; roll, pitch, yaw deg) or null")
    max_tilt_deg: Number | None = Field(default=None, gt=0.0, le=MAX_TILT_DEG,
                                       description="largest angle between the tool's z axis and the work frame's, deg")

    @field_validator("lower", "upper", mode="before")
    @classmethod
    def _six(cls, value: object) -> object:
        if not isinstance(value, (list, tuple)) or len(value) != 6:
            count = f", got {len(value)}" if isinstance(value, (list, tuple)) else ""
            raise ValueError(f"six bounds, one per axis x, y, z, roll, pitch, yaw (null: none){count}")
        return value

    @model_validator(mode="after")
    def _ordered(self) -> SoftLimits:
        if far := [f"{axis} {bound:g} {unit}" for axis, unit, low, high in zip(POSE_AXES, POSE_UNITS, self.lower,
                                                                                   self.upper)
                   for bound in (low, high) if bound is not None and abs(bound) > POSE_MAGNITUDE_LIMIT]:
            raise ValueError(f"soft bound {', '.join(far)} is beyond any platform's reach (at most "
                             f"±{POSE_MAGNITUDE_LIMIT:g} mm or deg): check the units and the number (null: no bound)")
        if across := [problem for axis, low, high in zip(range(6), self.lower, self.upper)
                      if (problem := _angle_window_problem(axis, low, high))]:
            raise ValueError("; ".join(across))
        crossed = [f"{axis} [{low:g}, {high:g}]" for axis, low, high in zip(POSE_AXES, self.lower, self.upper)
                   if low is not None and high is not None and not low < high]
        if crossed:
            raise ValueError(f"each lower bound must be below its upper bound: {', '.join(crossed)}")
        return self

    def violations(self, tool_in_work_mm_deg: Sequence[Sequence[float]] | NDArray) -> list[list[Violation]]:
        """For each of the (N, 6) poses of the tool in the work frame (mm, deg), the soft
        limits it breaks (kinds ``soft_limit``, naming the axis, and ``soft_tilt``); a pose
        within :data:`~hexactl.kinematics.workspace.POSE_BOUND_ROUNDING` of a bound is on it."""
        poses = np.array(tool_in_work_mm_deg, dtype=float).reshape(-1, 6)
        for axis in _TURNING_AXES:
            if (edge := self._edge(axis)) is not None:
                poses[np.abs(poses[:, axis]) >= _HALF_TURN_READ, axis] = edge
        found: list[list[Violation]] = [[] for _ in range(len(poses))]
        for bounds, side, broken, open_end, rounding in ((self.lower, "below", np.less, -np.inf, -POSE_BOUND_ROUNDING),
                                                         (self.upper, "above", np.greater, np.inf, POSE_BOUND_ROUNDING)):
            limits = np.array([open_end if bound is None else bound + rounding for bound in bounds])
            for n, axis in zip(*np.nonzero(broken(poses, limits))):
                value, limit, passed = self._way_round(axis, float(poses[n, axis]), side)
                unit = POSE_UNITS[axis]
                found[n].append(Violation(ViolationKind.SOFT_LIMIT, value, limit,
                                          f"{_LIMITED.format(POSE_AXES[axis])}, {value:.3f} {unit}, {passed} (by "
                                          f"{abs(value - limit):.3g} {unit})", axis=POSE_AXES[axis]))
        if self.max_tilt_deg is not None:
            for n, tilt in enumerate(tilt_deg(poses)):
                if self._beyond_tilt(tilt):
                    found[n].append(Violation(ViolationKind.SOFT_TILT, float(tilt), self.max_tilt_deg,
                                              f"{_LIMITED.format('tilt')}, {tilt:.3f} deg, beyond the soft limit "
                                              f"{self.max_tilt_deg:g} deg "
                                              f"(by {tilt - self.max_tilt_deg:.3g} deg)"))
        return found

    def allow(self, tool_in_work_mm_deg: Sequence[float]) -> bool:
        """Whether one pose of the tool in the work frame (mm, deg) breaks none of these
        limits: :meth:`violations` finds none. Plain floats for a stream's per-target check
        (:func:`~hexactl.kinematics.workspace.pose_within_limits` says why)."""
        for axis, value, low, high in zip(range(6), tool_in_work_mm_deg, self.lower, self.upper):
            if axis in _TURNING_AXES and abs(value) >= _HALF_TURN_READ and (edge := self._edge(axis)) is not None:
                value = edge
            if (low is not None and value < low - POSE_BOUND_ROUNDING) or \
                    (high is not None and value > high + POSE_BOUND_ROUNDING):
                return False
        if self.max_tilt_deg is None:
            return True
        roll, pitch = radians(tool_in_work_mm_deg[3]), radians(tool_in_work_mm_deg[4])
        return not self._beyond_tilt(degrees(acos(max(-1.0, min(1.0, cos(roll) * cos(pitch))))))

    def _way_round(self, axis: int, value: float, side: str) -> tuple[float, float, str]:
        """A ``value`` read ``side`` ("below", "above") its bounds on ``axis``, against the
        bound it is nearer: for roll or yaw turned past 180° out of a window up to it, the
        upper one (read -179 from [170, 180]: 181 above 180, not -179 below 170). A window
        open on one side ends there at ±180, where the angle reads to: read -179 from
        [170, null] is 181 above 180 too. As (value, bound, what it passed)."""
        low, high = self.lower[axis], self.upper[axis]
        bound = low if side == "below" else high
        if axis in _TURNING_AXES:
            low_end, high_end = -180.0 if low is None else low, 180.0 if high is None else high
            if side == "below" and value + 360.0 - high_end < low - value:
                value, bound, side = value + 360.0, high_end, "above"
            elif side == "above" and low_end - (value - 360.0) < value - high:
                value, bound, side = value - 360.0, low_end, "below"
        name, unit = POSE_AXES[axis], POSE_UNITS[axis]
        if bound in (low, high):
            return value, bound, f"{side} the soft limit {bound:g} {unit}"
        up = side == "above"  # past the open side's end, not a bound the operator set
        return value, bound, (f"{side} {bound:g} {unit}: {name} reads {'up' if up else 'down'} to {bound:g} {unit}, "
                              f"so its soft window {'from' if up else 'up to'} {low if up else high:g} {unit} ends "
                              "there")

    def _edge(self, axis: int) -> float | None:
        """How a reading of ±180° on roll or yaw (``axis``) is bounded: one orientation,
        read 180 or -180 as rounding goes, so 180 if that is within the bounds, else -180
        if that is, else None (outside either way, as read)."""
        low, high = self.lower[axis], self.upper[axis]
        if high is None or high >= _HALF_TURN_READ:
            return 180.0
        return -180.0 if low is None or low <= -_HALF_TURN_READ else None

    def _beyond_tilt(self, tilt: float) -> bool:
        return self.max_tilt_deg is not None and tilt > self.max_tilt_deg + POSE_BOUND_ROUNDING


def tilt_deg(poses_mm_deg: NDArray) -> NDArray[np.float64]:
    """The angle (deg) between the moving z axis and the frame's z axis of (N, 6) poses
    (mm, deg; orientation Rz·Ry·Rx): element (3, 3) of the rotation is cos(roll)·cos(pitch)
    (:meth:`SoftLimits.allow` has its plain-float copy)."""
    roll, pitch = np.radians(poses_mm_deg[:, 3]), np.radians(poses_mm_deg[:, 4])
    return np.degrees(np.arccos(np.clip(np.cos(roll) * np.cos(pitch), -1.0, 1.0)))


def _angle_window_problem(axis: int, low: Bound, high: Bound) -> str | None:
    """What is wrong with the bounds of ``axis`` if it is an angle and they reach beyond
    where it reads, or cross ±180°; None if nothing. An angle is compared as read, so such
    a window ([170, -170], [175, 185]) would be misread: refused, saying how to write it."""
    name, beyond = POSE_AXES[axis], max(abs(bound) for bound in (low, high, 0.0) if bound is not None)
    window = f"{name} [{_text(low)}, {_text(high)}] deg"
    if name == "pitch" and beyond > 90.0:
        return f"{window}: pitch reads in [-90, 90] deg: give bounds within it"
    if axis not in _TURNING_AXES:
        return None
    turned = _TURN_TOOL_FRAME[name]
    if low is not None and high is not None and high < low and beyond <= 180.0:
        return (f"{window} crosses ±180 deg, which soft limits do not support ({name} reads in [-180, 180] deg): "
                f"to keep {name} out of it, give [{high:g}, {low:g}]; to keep it within it, {turned[0]}, so that "
                f"the window no longer crosses ±180 deg: {name} then reads [{low - 180:g}, {high + 180:g}], "
                f"{turned[1]}")
    if beyond > 180.0:
        return (f"{window}: {name} reads in [-180, 180] deg, so a bound beyond is never reached and a window across "
                f"±180 deg is not supported: give bounds within [-180, 180] or, to keep {name} around 180 deg, "
                f"{turned[0]} ({name} then reads 180 deg less or more, {turned[1]})")
    return None


# How to turn a roll or yaw window away from ±180°, and what else it changes. The tool frame
# turned about its own axis (X·R) shifts that angle by 180° and leaves the position as it
# reads; the work frame turned instead (R⁻¹·X) would also change the sign of x and y (yaw)
# or of y, z, pitch and yaw (roll), which an operator would not expect.
_TURN_TOOL_FRAME = {
    "roll": ("add 180 deg to the tool frame's roll (a turn about its own x axis)", "the other axes as before"),
    "yaw": ("turn the tool frame by 180 deg about its own z axis (with its roll and pitch 0: add 180 deg to its yaw)",
            "roll and pitch with the opposite sign"),
}


def _text(bound: Bound) -> str:
    return "null" if bound is None else f"{bound:g}"


NO_SOFT_LIMITS = SoftLimits()
"""No bound at all: what an operator who set none has."""


class SoftLimitChanges(BaseModel):
    """Some soft limits to change, every other one kept: ``lower``/``upper`` by axis name
    (mm, deg; None: no bound on that side any more), ``max_tilt_deg`` when given (None: no
    tilt bound any more). ``SoftLimitChanges(lower={"x": -40})`` changes x's lower bound
    alone. Changed under the rules of :class:`SoftLimits` (:meth:`applied_to`)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    lower: Mapping[AxisName, Bound] = Field(default_factory=dict, description="lower bounds to change, by axis "
                                            "(x, y, z mm; roll, pitch, yaw deg); null: none on that side any more")
    upper: Mapping[AxisName, Bound] = Field(default_factory=dict, description="upper bounds to change, likewise")
    max_tilt_deg: Number | None = Field(default=None, gt=0.0, le=MAX_TILT_DEG, description="the tilt bound, deg, "
                                       "if given (null: none any more); not given: kept")

    def applied_to(self, limits: SoftLimits) -> SoftLimits:
        """``limits`` with these changes.

        :raises pydantic.ValidationError: the soft limits that result break a rule of
            :class:`SoftLimits` (a lower bound set above the upper one kept, say)
        """
        lower, upper = list(limits.lower), list(limits.upper)
        for bounds, changes in ((lower, self.lower), (upper, self.upper)):
            for axis, bound in changes.items():
                bounds[POSE_AXES.index(axis)] = bound
        tilt = self.max_tilt_deg if "max_tilt_deg" in self.model_fields_set else limits.max_tilt_deg
        return SoftLimits(lower=tuple(lower), upper=tuple(upper), max_tilt_deg=tilt)
