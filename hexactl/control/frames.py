"""The operator's work and tool frames and soft limits, as the facade plans with them.

The work frame is set as a pose in the zero frame (the platform's frame at the zero
posture of the active calibration), the tool frame as a pose in the platform's frame; its
origin is the pivot point. A motion in the work frame is planned and run in the tool's
pose in the work frame (:class:`~hexactl.kinematics.axes.ToolInWorkMmRad`), so a
rotation turns about the pivot point along the whole path, not only at the goal.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum
from math import pi, remainder, tau
from operator import add, sub

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator

from hexactl.kinematics.axes import (
    POSE_AXES,
    FramePoseMmDeg,
    RelativeMmDeg,
    RelativeMmRad,
    ToolInWorkMmDeg,
    ToolInWorkMmRad,
    bounds_text,
)
from hexactl.kinematics.frames import Frames, compose, platform_poses, pose_of, transform_of
from hexactl.kinematics.soft_limits import NO_SOFT_LIMITS, SoftLimits

MAX_FRAME_OFFSET_MM = 10_000.0
"""How far a frame's origin may be from its parent's along each axis: beyond, a typo."""

ZERO_FRAME = FramePoseMmDeg(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class OperatorFrames(BaseModel):
    """``work``: the work frame in the zero frame; ``tool``: the tool frame in the
    platform's frame (both mm, deg; angles in [-180, 180]); ``soft_limits`` on the tool's
    pose in the work frame.

    :raises pydantic.ValidationError: naming the frame, the axis and the bound
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    work: FramePoseMmDeg = Field(default=ZERO_FRAME, description="the work frame in the zero frame, mm and deg")
    tool: FramePoseMmDeg = Field(default=ZERO_FRAME, description="the tool frame (origin: the pivot point) in the "
                                 "platform's frame, mm and deg")
    soft_limits: SoftLimits = Field(default=NO_SOFT_LIMITS, description="bounds on the tool's pose in the work frame")

    @field_validator("work", "tool")
    @classmethod
    def _sane(cls, pose: FramePoseMmDeg) -> FramePoseMmDeg:
        for axis, value in zip(POSE_AXES, pose):
            bound, unit = (MAX_FRAME_OFFSET_MM, "mm") if axis in ("x", "y", "z") else (180.0, "deg")
            if not -bound <= value <= bound:
                raise ValueError(f"{axis} {value:g} {unit} is outside [{-bound:g}, {bound:g}] {unit}")
        return pose

    def text(self) -> str:
        """For people, as an event says what was set: the frames (mm, deg) and the soft limits."""
        if self == OperatorFrames():
            return "none: no work frame, no tool frame, no soft limits"
        limits = self.soft_limits

        def pose(values: Sequence[float]) -> str:
            return ", ".join(f"{value:g}" for value in values)

        return (f"work frame ({pose(self.work)}), tool frame ({pose(self.tool)}) (mm, deg); soft limits "
                f"{bounds_text(limits.lower, limits.upper, limits.max_tilt_deg)}")

    def frames(self, home_mm_rad: tuple[float, ...]) -> Frames:
        """The frames as rigid transforms in the fixed frame, for a calibration whose zero
        posture is ``home_mm_rad`` (absolute, mm and rad)."""
        return Frames(compose(transform_of(home_mm_rad), transform_of(self.work.in_radians())),
                      transform_of(self.tool.in_radians()))


Coordinates = RelativeMmRad | ToolInWorkMmRad
"""A motion's position: relative to the zero posture (frames None), or the tool's pose
in the work frame of the frames it runs in."""


def relative_poses(frames: Frames | None, positions: NDArray, home_mm_rad: Sequence[float]) -> NDArray[np.float64]:
    """(N, 6) positions in the coordinates of ``frames`` (None: already relative) as poses
    relative to the zero posture ``home_mm_rad``, mm and rad."""
    if frames is None:
        return positions
    return platform_poses(frames, positions) - np.asarray(home_mm_rad)


def convert(position: Sequence[float], source: Frames | None, target: Frames | None,
            home_mm_rad: Sequence[float]) -> Coordinates:
    """A position in the coordinates of ``source`` in those of ``target`` (None: relative
    to the zero posture ``home_mm_rad``); mm and rad. In the same coordinates it is the
    position itself, its angles where the motion left them (:func:`short_way`)."""
    if source == target:
        return (RelativeMmRad if target is None else ToolInWorkMmRad)._make(map(float, position))
    absolute = source.platform_pose(position) if source is not None else tuple(map(add, home_mm_rad, position))
    if target is None:
        return tuple.__new__(RelativeMmRad, map(sub, absolute, home_mm_rad))
    return ToolInWorkMmRad._make(target.tool_in_work(absolute))


class Frame(StrEnum):
    """The frame a commanded pose is in."""

    ZERO = "zero"  # the platform relative to the zero posture, component by component (the default)
    WORK = "work"  # the tool's pose in the work frame
    TOOL = "tool"  # relative moves only: a displacement along and about the tool's own axes, at the pivot


def requested_goal(pose_mm_deg: Sequence[float], frame: Frame, relative: bool, target: Coordinates,
                   target_frames: Frames | None, operator: Frames, home_mm_rad: Sequence[float]
                   ) -> RelativeMmDeg | ToolInWorkMmDeg | str:
    """The goal of a move to ``pose_mm_deg`` in ``frame``, as an absolute pose in the zero
    or the work frame; with ``relative`` it is added to ``target`` (where the motion
    under way is headed, in the coordinates of ``target_frames``): component by component
    in the zero and the work frame, composed on the tool's own axes in the tool frame.
    What is wrong, as a sentence, for an absolute pose in the tool frame."""
    pose = [float(value) for value in pose_mm_deg]
    if frame is Frame.ZERO:
        if not relative:
            return RelativeMmDeg._make(pose)
        base = convert(target, target_frames, None, home_mm_rad).in_degrees()
        return RelativeMmDeg._make(map(add, base, pose))
    if not relative:
        if frame is Frame.TOOL:
            return "a pose in the tool frame is a relative move (relative: true): the tool is always at its own origin"
        return ToolInWorkMmDeg._make(pose)
    base = convert(target, target_frames, operator, home_mm_rad)
    if frame is Frame.WORK:
        return ToolInWorkMmDeg._make(map(add, base.in_degrees(), pose))
    moved = compose(transform_of(base), transform_of(ToolInWorkMmDeg._make(pose).in_radians()))
    return short_way(base, ToolInWorkMmRad._make(pose_of(moved))).in_degrees()


def short_way(start: Sequence[float], goal: ToolInWorkMmRad) -> ToolInWorkMmRad:
    """``goal`` (mm, rad) with each angle in [-180°, 180°] that is more than half a turn
    from ``start``'s moved by a whole turn to within it: the same pose, reached turning the
    short way round. Such an angle names an orientation, as one is read back, and a motion
    in the work frame need not have left its angles in that range (a turn from -170° by
    -15° ends at -185°; with the work frame turned 180°, yaw 180° is where it reads -180°).
    An angle beyond ±180° is taken as it is, and refused where out of reach."""
    return ToolInWorkMmRad._make((*goal[:3], *(s + remainder(g - s, tau) if abs(g) <= pi < abs(g - s) else g
                                               for s, g in zip(start[3:], goal[3:]))))
