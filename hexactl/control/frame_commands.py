"""The facade's frame commands: the operator's work and tool frames and soft limits,
which every plan reads and a command replaces whole."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.frames import OperatorFrames
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.kinematics.axes import POSE_AXES
from hexactl.kinematics.frames import tools_in_work
from hexactl.kinematics.pose import absolute_from_relative, pose_mm_rad_to_mm_deg

REACH_SLACK = 0.1
"""Of the span the tool's x, y or z covers over the pose envelope's corners, how far
beyond it a soft bound is still taken to limit something: between the corners the
reach is not linear in the angles."""


def bounds_beyond_reach(frames: OperatorFrames, home_mm_rad: tuple[float, ...], pose_min: Sequence[float],
                        pose_max: Sequence[float]) -> list[str]:
    """The soft bounds on x, y and z (mm) of ``frames`` beyond anywhere the tool can go in
    its work frame within the pose envelope ``pose_min``..``pose_max`` (relative mm and
    deg), as notes: such a bound limits nothing. Found from outside: x -5000..5000 mm was
    taken without a word, as a unit slip for 50.00 would be. Judged at the envelope's 64
    corners, :data:`REACH_SLACK` to spare."""
    corners = np.array(list(itertools.product(*zip(pose_min, pose_max))), dtype=float)
    home_mm_deg = pose_mm_rad_to_mm_deg(home_mm_rad)
    reach = pose_mm_rad_to_mm_deg(tools_in_work(frames.frames(home_mm_rad),
                                                absolute_from_relative(home_mm_deg, corners)))
    notes = []
    for axis in range(3):
        low, high = float(reach[:, axis].min()), float(reach[:, axis].max())
        spare = REACH_SLACK * (high - low)
        for side, bound in (("lower", frames.soft_limits.lower[axis]), ("upper", frames.soft_limits.upper[axis])):
            if bound is not None and not low - spare <= bound <= high + spare:
                notes.append(f"{POSE_AXES[axis]} {side} bound {bound:g} mm is beyond where the tool can go "
                             f"({POSE_AXES[axis]} {low:.0f}..{high:.0f} mm over the pose envelope): it limits nothing "
                             "(a unit slip?)")
    return notes


class FrameCommands:
    """Holds the :class:`~hexactl.control.frames.OperatorFrames` of one facade. Read and
    replaced from any thread: a replacement is one reference swap, and a plan reads the
    reference once. A motion under way keeps the frames it was planned in."""

    def __init__(self, frames: OperatorFrames, snapshot: Callable[[], CoreSnapshot],
                 submitter: CommandSubmitter) -> None:
        self.current = frames
        self._snapshot = snapshot
        self._submitter = submitter

    def set(self, frames: OperatorFrames) -> CommandResult:
        """Make ``frames`` the operator's, at rest only (``busy`` while a motion, sequence,
        wave or stream is under way or a sequence is paused); refused
        (``outside_soft_limits``) when the pose being commanded breaks its soft limits,
        since no move could then start."""
        if not isinstance(frames, OperatorFrames):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "set_frames takes validated OperatorFrames")
        s = self._snapshot()
        if refusal := preconditions.check_set_frames(s):
            return CommandResult.failure(*refusal)
        home = s.active.home
        tool = tools_in_work(frames.frames(home), np.asarray(s.pose_command) + np.asarray(home))
        (broken,) = frames.soft_limits.violations(pose_mm_rad_to_mm_deg(tool))
        if broken:
            return CommandResult.failure(
                ErrorCode.OUTSIDE_SOFT_LIMITS,
                f"the platform is outside these soft limits ({'; '.join(v.message for v in broken)}): move it inside "
                "first, or widen them", violations=[v.message for v in broken])
        self.current = frames
        text = frames.text()  # the loop's log says what they are now, and who set them
        self._submitter.submit(lambda ticket: cmd.FramesSet(ticket, text), "noted")
        limits = s.active.geometry.limits
        notes = bounds_beyond_reach(frames, home, limits.pose_min, limits.pose_max)
        return self.result("frames set" + "".join(f"; note: {note}" for note in notes))

    def result(self, message: str = "frames") -> CommandResult:
        """The operator's frames and soft limits (mm, deg) as a result's details."""
        return CommandResult.success(message, frames=self.current.model_dump(mode="json"))
