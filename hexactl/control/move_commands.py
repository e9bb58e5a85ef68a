"""The facade's moves: validate or make a move to a pose, with the predicted accuracy at
its goal (:mod:`hexactl.control.accuracy`) and what it was validated under
(:mod:`hexactl.control.validated_under`); and the result of any path's plan."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.accuracy import predicted_accuracy, tolerance_refusal
from hexactl.control.frames import Frame, OperatorFrames, convert, requested_goal
from hexactl.control.planning import Plan, PlanningContext, Refusal, Waypoint, plan_path
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.validated_under import (ValidatedUnder, changed_since_validation, goal_changed,
                                              why_the_goal_moves)
from hexactl.kinematics.axes import POSE_AXES, validate_pose_values


class MoveCommands:
    """Moves of one facade: ``snapshot()`` the loop's latest, ``frames()`` the operator's
    frames in force, ``context(snapshot, frames)`` what a plan depends on, commands queued
    by ``submitter``."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], frames: Callable[[], OperatorFrames],
                 context: Callable[[CoreSnapshot, OperatorFrames], PlanningContext],
                 submitter: CommandSubmitter) -> None:
        self._snapshot = snapshot
        self._frames = frames
        self._context = context
        self._submitter = submitter

    def validate(self, pose: Sequence[float], duration: float | None, speed: float | None, frame: Frame,
                 relative: bool, tolerance_mm: float | None, validated_under: ValidatedUnder | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.validate_pose`."""
        s = self._snapshot()
        goal = self._checked_goal(s, pose, duration, speed, frame, relative, tolerance_mm, validated_under,
                                  accuracy_wanted=True)
        if isinstance(goal, CommandResult):
            return goal
        result = plan_result(goal.plan, "valid", s.active.home)
        return CommandResult.success(result.message, **result.details, predicted_accuracy=goal.accuracy,
                                     validated_under=goal.validated_under)

    def move(self, pose: Sequence[float], duration: float | None, speed: float | None, frame: Frame,
             relative: bool, tolerance_mm: float | None, validated_under: ValidatedUnder | None,
             deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.move`."""
        s = self._snapshot()
        if refusal := preconditions.check_move(s):
            return CommandResult.failure(*refusal)
        goal = self._checked_goal(s, pose, duration, speed, frame, relative, tolerance_mm, validated_under,
                                  accuracy_wanted=False)
        if isinstance(goal, CommandResult):
            return goal
        (segment,) = goal.plan.segments
        return self._submitter.submit(lambda t: cmd.Move(t, s.epoch, segment), "moving", deadline_ns=deadline_ns,
                                      **plan_result(goal.plan, "", s.active.home).details)

    def accuracy_now(self) -> dict[str, Any] | None:
        """See :meth:`hexactl.control.controller.Controller.predicted_accuracy`."""
        s = self._snapshot()
        return predicted_accuracy(s.active, self._frames().tool[:3], s.pose_command)

    def _checked_goal(self, s: CoreSnapshot, pose: Sequence[float], duration: float | None, speed: float | None,
                      frame: Frame, relative: bool, tolerance_mm: float | None,
                      validated_under: ValidatedUnder | None, *, accuracy_wanted: bool) -> _CheckedGoal | CommandResult:
        """The move's plan from ``s`` in the frames in force, with every check a move has,
        or the refusal. The accuracy at the goal is computed where ``accuracy_wanted`` or a
        ``tolerance_mm`` needs it."""
        frames = self._frames()
        if refusal := changed_since_validation(validated_under, s.active.calibration_id, frames):
            return refusal
        plan = self._plan(s, frames, pose, duration, speed, frame, relative)
        if not plan.ok:
            return plan_result(plan, "", s.active.home)
        last = plan.segments[-1]
        goal = convert(last.goal, last.frames, None, s.active.home)
        if refusal := goal_changed(validated_under, goal.in_degrees(),
                                   why_the_goal_moves(relative, s.lock.leg if s.lock is not None else None)):
            return refusal
        accuracy = None
        if accuracy_wanted or tolerance_mm is not None:
            accuracy = predicted_accuracy(s.active, frames.tool[:3], goal)
        if refusal := tolerance_refusal(tolerance_mm, accuracy):
            return refusal
        return _CheckedGoal(plan, accuracy, ValidatedUnder(calibration_id=s.active.calibration_id, frames=frames,
                                                           goal=goal.in_degrees()))

    def _plan(self, s: CoreSnapshot, frames: OperatorFrames, pose: Sequence[float], duration: float | None,
              speed: float | None, frame: Frame, relative: bool) -> Plan:
        context = self._context(s, frames)
        if problem := validate_pose_values(pose) or (None if frame in tuple(Frame) else f"unknown frame {frame!r}"):
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, problem))
        if relative and (beyond := [(axis, turn) for axis, turn in zip(POSE_AXES[3:], pose[3:]) if abs(turn) > 180]):
            # a goal in the work frame is reached the short way round (short_way): such a
            # turn would go the other way, to the same orientation
            got = ", ".join(f"{axis} {_micro_degrees(turn)}°" for axis, turn in beyond)
            same = ", ".join(f"{axis} {_micro_degrees((turn + 180.0) % 360.0 - 180.0, '+')}°" for axis, turn in beyond)
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, f"a relative turn is at most 180° about each axis, "
                                        f"got {got}: the same orientation is {same}"))
        goal = requested_goal(pose, Frame(frame), bool(relative), s.target, s.frames, context.frames, s.active.home)
        if isinstance(goal, str):
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, goal))
        return plan_path(context, s.trajectory, [Waypoint(goal, duration, speed)], s.frames)


@dataclass(frozen=True, slots=True)
class _CheckedGoal:
    """A move's plan that passed every check, the predicted accuracy at its goal (None:
    not asked for, or no calibration covariance) and what it was validated under."""

    plan: Plan
    accuracy: dict[str, Any] | None
    validated_under: ValidatedUnder


def plan_result(plan: Plan, message: str, home_mm_rad: Sequence[float]) -> CommandResult:
    """The result of ``plan``: its refusal, or ``goal`` relative to the zero posture
    ``home_mm_rad`` (and ``tool_goal``, the tool's pose in the work frame, for a motion in
    it; mm and deg), ``duration_s``, ``waypoints`` and, in leg-lock mode,
    ``lock_corrections_mm`` (:attr:`~hexactl.control.planning.Plan.lock_corrections_mm`)."""
    if plan.refusal is not None:
        return plan.refusal.result()
    last = plan.segments[-1]
    in_work = {"tool_goal": list(last.goal.in_degrees())} if last.frames is not None else {}
    locked = {"lock_corrections_mm": list(plan.lock_corrections_mm)} if plan.lock_corrections_mm else {}
    return CommandResult.success(
        message,
        goal=list(convert(last.goal, last.frames, None, home_mm_rad).in_degrees()),
        duration_s=sum(seg.duration_s + seg.dwell_s for seg in plan.segments),
        waypoints=len(plan.segments),
        **in_work,
        **locked,
    )


def _micro_degrees(angle: float, sign: str = "") -> str:
    """``angle`` (deg) to the µ°, trailing zeros dropped: 180.0001 is no "180" (:g's six
    digits), whose other way round is no "-180"; never "-0"."""
    return f"{round(angle, 6) + 0.0:{sign}.6f}".rstrip("0").rstrip(".")
