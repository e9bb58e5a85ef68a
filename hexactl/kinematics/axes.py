"""The pose's axes, their units at the edges, a type for each pose convention, and what
makes six values a pose.

Standard library only, so that the command line parses a pose without loading numpy;
the conversions are in :mod:`hexactl.kinematics.pose`.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import degrees, isfinite, radians
from typing import Any, Literal, NamedTuple, TypeAlias

POSE_AXES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
"""Axis names in pose order; the first three in mm, the last three in degrees at the edges."""

POSE_UNITS: tuple[str, ...] = ("mm", "mm", "mm", "deg", "deg", "deg")

AxisName = Literal["x", "y", "z", "roll", "pitch", "yaw"]
"""One of :data:`POSE_AXES`, where a message or a file names an axis."""

MAX_TILT_DEG = 90.0
"""The largest bound on a tool's tilt (the angle between its z axis and the work frame's,
:mod:`hexactl.kinematics.soft_limits`): beyond it the tool's z axis points down."""

def bounds_text(lower: Sequence[float | None], upper: Sequence[float | None], max_tilt_deg: float | None) -> str:
    """Soft limits for people: ``x -50..50 mm, z ≥ -10 mm, tilt ≤ 5 deg``, or ``none``
    (per axis in its unit, None: no bound on that side)."""
    parts = []
    for axis, unit, low, high in zip(POSE_AXES, POSE_UNITS, lower, upper):
        if low is not None and high is not None:
            parts.append(f"{axis} {low:g}..{high:g} {unit}")
        elif low is not None or high is not None:
            parts.append(f"{axis} {'≥' if low is not None else '≤'} {low if low is not None else high:g} {unit}")
    if max_tilt_deg is not None:
        parts.append(f"tilt ≤ {max_tilt_deg:g} deg")
    return ", ".join(parts) or "none"


PerAxis: TypeAlias = tuple[float, float, float, float, float, float]
"""One value per pose axis, in that axis's units (a limit, a velocity): not a pose."""


class _SixAxes(NamedTuple):
    """The six values of a pose. Each convention below is its own subclass, so that a pose's
    frame and units are in its type; they are tuples, so numpy and the hot loop take them
    as they are."""

    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float

    @classmethod
    def __get_pydantic_core_schema__(cls, source: type, handler: Any) -> Any:
        """Validated by pydantic as six finite numbers (a model's ``allow_inf_nan=False``),
        with :func:`validate_pose_values`'s sentence for a wrong count, into this type.

        Built on a list of floats, not on the NamedTuple pydantic would make of the class:
        that one is a shared definition, and a second field of the same type in a model got
        it without the count check. A list, so that strict models take JSON arrays and
        tuples alike."""
        from pydantic_core import core_schema  # only where pydantic builds a model: the CLI parses poses without it

        def six(value: object) -> object:  # a list or tuple (not a mapping) of six
            if not isinstance(value, (list, tuple)) or len(value) != 6:
                raise ValueError(validate_pose_values(value) or "a pose is six numbers [x, y, z, roll, pitch, yaw]")
            return list(value)

        def made(values: list[float]) -> _SixAxes:  # within reach of any platform, in the type: every model checks it
            if problem := validate_pose_values(values):
                raise ValueError(problem)
            return cls._make(values)

        # strict numbers: a file's "1.5" or true is a slip to refuse (hexactl.kinematics.numbers)
        values = core_schema.list_schema(core_schema.float_schema(strict=True), min_length=6, max_length=6)
        return core_schema.no_info_before_validator_function(six, core_schema.no_info_after_validator_function(
            made, values, serialization=core_schema.plain_serializer_function_ser_schema(list)))


class RelativeMmDeg(_SixAxes):
    """Relative to the zero posture, mm and degrees: what the API, the CLI and files carry."""

    __slots__ = ()

    def in_radians(self) -> RelativeMmRad:
        return RelativeMmRad(self.x, self.y, self.z, radians(self.roll), radians(self.pitch), radians(self.yaw))


class RelativeMmRad(_SixAxes):
    """Relative to the zero posture, mm and radians: what planning and the loop work in."""

    __slots__ = ()

    def in_degrees(self) -> RelativeMmDeg:
        return RelativeMmDeg(self.x, self.y, self.z, degrees(self.roll), degrees(self.pitch), degrees(self.yaw))


class AbsoluteMmDeg(_SixAxes):
    """In the fixed frame, mm and degrees: the zero posture in geometry files, and measured
    poses in measurement files."""

    __slots__ = ()

    def in_radians(self) -> AbsoluteMmRad:
        return AbsoluteMmRad(self.x, self.y, self.z, radians(self.roll), radians(self.pitch), radians(self.yaw))


class AbsoluteMmRad(_SixAxes):
    """In the fixed frame, mm and radians: what the kinematics works in."""

    __slots__ = ()


class ToolInWorkMmDeg(_SixAxes):
    """The tool frame's pose in the work frame, mm and degrees (see
    :mod:`hexactl.kinematics.frames`): what the API, the CLI and files carry for a pose in
    the work frame."""

    __slots__ = ()

    def in_radians(self) -> ToolInWorkMmRad:
        return ToolInWorkMmRad(self.x, self.y, self.z, radians(self.roll), radians(self.pitch), radians(self.yaw))


class ToolInWorkMmRad(_SixAxes):
    """The tool frame's pose in the work frame, mm and radians: what a motion in the work
    frame is planned and run in."""

    __slots__ = ()

    def in_degrees(self) -> ToolInWorkMmDeg:
        return ToolInWorkMmDeg(self.x, self.y, self.z, degrees(self.roll), degrees(self.pitch), degrees(self.yaw))


class FramePoseMmDeg(_SixAxes):
    """Where a frame an operator defines is in its parent, mm and degrees: the work frame
    in the zero frame (the platform's frame at the zero posture), the tool frame in the
    platform's frame."""

    __slots__ = ()

    def in_radians(self) -> tuple[float, float, float, float, float, float]:
        return (self.x, self.y, self.z, radians(self.roll), radians(self.pitch), radians(self.yaw))


POSE_MAGNITUDE_LIMIT = 1e6
"""The largest magnitude a pose component may have (mm or deg): far beyond any platform's
reach and any sensible angle, and small enough that squaring it cannot overflow."""


def validate_pose_values(pose: Sequence[float]) -> str | None:
    """None when ``pose`` is six finite numbers within ±:data:`POSE_MAGNITUDE_LIMIT`, else a
    sentence naming the problem."""
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        return "a pose is six numbers [x, y, z, roll, pitch, yaw]"
    if len(values) != 6:
        return f"a pose is six numbers [x, y, z, roll, pitch, yaw], got {len(values)}"
    bad = [POSE_AXES[i] for i, v in enumerate(values) if not isfinite(v)]
    if bad:
        return f"pose {', '.join(bad)} is not a finite number"
    huge = [f"{POSE_AXES[i]} {v:g}" for i, v in enumerate(values) if abs(v) > POSE_MAGNITUDE_LIMIT]
    if huge:
        return (f"pose {', '.join(huge)} is beyond any platform's reach (at most ±{POSE_MAGNITUDE_LIMIT:g} mm or deg); "
                "check the units and the number")
    return None
