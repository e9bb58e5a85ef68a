"""What a move was validated under, so that it is refused once that is no longer in force.

A move's goal depends on more than its request: a pose in the work or tool frame is
another platform pose once the operator's frames change, and the same pose relative to
the zero posture other leg lengths once the calibration changes. Planned anew at Go, a
move validated before such a change passes its checks and goes where the new frames put
it, not to the goal its operator saw; and a relative move starts from the target, so once
the platform has moved (another client's move, a jog, a stop that braked short) it goes
elsewhere too. So ``validate_pose`` says what it validated under and the goal it validated
(:class:`ValidatedUnder`), a client sends that back with the ``move``, and the facade
refuses the move (``changed_since_validation``) if anything of it changed meanwhile
(:func:`changed_since_validation`) or the move's goal is no longer the one validated
(:func:`goal_changed`).

A move validated in one enabled spell and sent after an E-stop and a re-enable is not
refused for that alone: its goal, frames and calibration are checked as above, and its
path is planned and checked anew from where the platform is, as every move's is.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from hexactl.control.frames import OperatorFrames
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS, RelativeMmDeg

GOAL_TOLERANCE = 1e-6
"""How far a move's goal may lie from the goal validated (mm in x, y, z; degrees in roll,
pitch, yaw) and still be the same goal: a nanometre, far below any actuator's resolution,
above the rounding of planning the same request twice."""


class ValidatedUnder(BaseModel):
    """The active calibration's id and the operator's frames and soft limits (mm, deg)
    a move was planned under, and the goal it was planned to."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    calibration_id: str = Field(min_length=1, max_length=64, description="the active calibration's id (content hash)")
    frames: OperatorFrames = Field(description="the operator's frames and soft limits, as telemetry's frames")
    goal: RelativeMmDeg = Field(description="the goal validated, relative to the zero posture, mm and deg")

    def changes_to(self, calibration_id: str, frames: OperatorFrames) -> list[str]:
        """What differs in ``calibration_id`` and ``frames`` (in force now) of what the
        goal was planned under, named for people (empty: nothing); the goal itself is
        :func:`goal_changed`'s."""
        before = self.frames
        differs = {"work frame": before.work != frames.work, "tool frame": before.tool != frames.tool,
                   "soft limits": before.soft_limits != frames.soft_limits,
                   "calibration": self.calibration_id != calibration_id}
        return [name for name, changed in differs.items() if changed]


def changed_since_validation(validated: ValidatedUnder | None, calibration_id: str,
                             frames: OperatorFrames) -> CommandResult | None:
    """The refusal of a move validated under ``validated`` (None: not said, nothing to
    check) when ``calibration_id`` and ``frames`` are in force instead:
    ``changed_since_validation``, naming what changed (``details.changed``) and with what
    is in force (``details.in_force``: ``calibration_id``, ``frames``)."""
    changed = validated.changes_to(calibration_id, frames) if validated is not None else []
    if not changed:
        return None
    what = " and the ".join(changed)
    return CommandResult.failure(
        ErrorCode.CHANGED_SINCE_VALIDATION,
        f"the {what} changed since this move was validated (another client may have changed "
        f"{'them' if len(changed) > 1 else 'it'}): the move could go elsewhere than the goal validated, so nothing "
        "moved; validate it again, check the new goal, then move",
        changed=changed, in_force={"calibration_id": calibration_id, "frames": frames})


def goal_changed(validated: ValidatedUnder | None, goal: RelativeMmDeg, because: str) -> CommandResult | None:
    """The refusal of a move validated under ``validated`` (None: nothing to check) whose
    goal, planned now, is ``goal`` instead of the one validated (by more than
    :data:`GOAL_TOLERANCE` on an axis): ``changed_since_validation``, ``details.changed``
    ``["goal"]``, with both goals (``details.validated_goal``, ``details.goal``).
    ``because``: why it may have changed, for people (:func:`why_the_goal_moves`)."""
    if validated is None:
        return None
    moved = [f"{axis} {before:.6g} → {after:.6g} {unit}"
             for axis, unit, before, after in zip(POSE_AXES, POSE_UNITS, validated.goal, goal)
             if abs(after - before) > GOAL_TOLERANCE]
    if not moved:
        return None
    return CommandResult.failure(
        ErrorCode.CHANGED_SINCE_VALIDATION,
        f"the goal changed since this move was validated ({', '.join(moved)}): {because}, so the move would go "
        "elsewhere than the goal validated; nothing moved; validate it again, check the new goal, then move",
        changed=["goal"], validated_goal=list(validated.goal), goal=list(goal))


def why_the_goal_moves(relative: bool, locked_leg: int | None) -> str:
    """What makes a move's goal, planned again, another than the one validated: a relative
    move's start (the target), and a locked leg's constraint, which the goal is projected on."""
    causes = []
    if relative:
        causes.append("a relative move starts from the target, and the platform has moved since (another client's "
                      "move, a jog or a stop)")
    if locked_leg is not None:
        causes.append(f"leg {locked_leg} is locked, and the goal is projected onto its constraint (locked or moved "
                      "since the validation)")
    return "; ".join(causes) or "the platform's state changed since"
