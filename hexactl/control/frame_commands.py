"""The facade's frame commands: the operator's work and tool frames and soft limits,
which every plan reads and a command replaces whole."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.frames import OperatorFrames
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.kinematics.frames import tools_in_work
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg


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
        return self.result("frames set")

    def result(self, message: str = "frames") -> CommandResult:
        """The operator's frames and soft limits (mm, deg) as a result's details."""
        return CommandResult.success(message, frames=self.current.model_dump(mode="json"))
