"""The facade's sequences: validate or play a sequence (or a built-in one by name), pause,
resume and abort it (:mod:`hexactl.control.sequence_player` plays it in the loop)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.move_commands import plan_result
from hexactl.control.planning import PlanningContext, Waypoint, plan_path
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.sequences import BUILTIN_SEQUENCES, MotionSequence, UnknownSequence, builtin_sequence
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.trajectory import KinematicState


class SequenceCommands:
    """Sequences of one facade: ``snapshot()`` the loop's latest, ``context(snapshot)``
    what a plan depends on, commands queued by ``submitter``."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], context: Callable[[CoreSnapshot], PlanningContext],
                 submitter: CommandSubmitter) -> None:
        self._snapshot = snapshot
        self._context = context
        self._submitter = submitter

    def validate(self, sequence: MotionSequence | str) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.validate_sequence`."""
        resolved = _resolve(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self._snapshot()
        # From where the motion under way ends, at rest: play needs rest (as a wave does).
        start = KinematicState.at_rest(s.target)
        return plan_result(plan_path(self._context(s), start, resolved.planning_waypoints(), s.frames), "valid",
                           s.active.home)

    def play(self, sequence: MotionSequence | str, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.play`."""
        resolved = _resolve(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self._snapshot()
        if refusal := preconditions.check_play(s):
            return CommandResult.failure(*refusal)
        plan = plan_path(self._context(s), s.trajectory, resolved.planning_waypoints(), s.frames)
        if not plan.ok:
            return plan_result(plan, "", s.active.home)
        name = resolved.name
        return self._submitter.submit(lambda t: cmd.Play(t, s.epoch, name, plan.segments), f"playing {name}",
                                      deadline_ns=deadline_ns, **plan_result(plan, "", s.active.home).details)

    def pause(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.pause`."""
        return self._submitter.submit_unless(preconditions.check_pause, cmd.Pause, "pausing")

    def resume(self, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.resume`."""
        s = self._snapshot()
        if refusal := preconditions.check_resume(s):
            return CommandResult.failure(*refusal)
        progress = s.sequence
        assert progress is not None
        remainder = None
        if progress.paused_in_move:
            segment = progress.segment
            waypoint = Waypoint(segment.goal.in_degrees(), None, segment.velocity_scale / segment.time_scale)
            context = self._context(s)  # the remainder runs in the frames the segment was planned in
            plan = plan_path(replace(context, frames=segment.frames or context.frames), s.trajectory, [waypoint], s.frames)
            if not plan.ok:
                return plan_result(plan, "", s.active.home)
            (remainder,) = plan.segments
        return self._submitter.submit(lambda t: cmd.Resume(t, s.epoch, remainder), "resumed", deadline_ns=deadline_ns)

    def abort(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.abort`."""
        return self._submitter.submit_unless(preconditions.check_abort, cmd.Abort, "aborted")


def _resolve(sequence: object) -> MotionSequence | CommandResult:
    """A sequence, a built-in one by name, or the refusal."""
    if isinstance(sequence, str):
        try:
            return builtin_sequence(sequence)
        except UnknownSequence as error:
            return CommandResult.failure(ErrorCode.UNKNOWN_SEQUENCE, str(error), built_in=list(BUILTIN_SEQUENCES))
    if not isinstance(sequence, MotionSequence):
        return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "a sequence is a MotionSequence or a built-in name")
    return sequence
