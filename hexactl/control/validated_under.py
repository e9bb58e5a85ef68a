"""What a move was validated under, so that it is refused once that is no longer in force.

A move's goal depends on more than its request: a pose in the work or tool frame is
another platform pose once the operator's frames change, and the same pose relative to
the zero posture other leg lengths once the calibration changes. Planned anew at Go, a
move validated before such a change passes its checks and goes where the new frames put
it, not to the goal its operator saw. So ``validate_pose`` says what it validated under
(:class:`ValidatedUnder`), a client sends that back with the ``move``, and the facade
refuses the move (``changed_since_validation``) if anything of it changed meanwhile
(:func:`changed_since_validation`).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from hexactl.control.frames import OperatorFrames
from hexactl.control.results import CommandResult, ErrorCode


class ValidatedUnder(BaseModel):
    """The active calibration's id and the operator's frames and soft limits (mm, deg)
    a move was planned under."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    calibration_id: str = Field(min_length=1, max_length=64, description="the active calibration's id (content hash)")
    frames: OperatorFrames = Field(description="the operator's frames and soft limits, as telemetry's frames")

    def changes_to(self, now: ValidatedUnder) -> list[str]:
        """What differs in ``now``, named for people (empty: nothing)."""
        before, after = self.frames, now.frames
        differs = {"work frame": before.work != after.work, "tool frame": before.tool != after.tool,
                   "soft limits": before.soft_limits != after.soft_limits,
                   "calibration": self.calibration_id != now.calibration_id}
        return [name for name, changed in differs.items() if changed]


def changed_since_validation(validated: ValidatedUnder | None, now: ValidatedUnder) -> CommandResult | None:
    """The refusal of a move validated under ``validated`` (None: not said, nothing to
    check) when ``now`` is in force instead: ``changed_since_validation``, naming what
    changed (``details.changed``) and with what is in force (``details.in_force``)."""
    changed = validated.changes_to(now) if validated is not None else []
    if not changed:
        return None
    what = " and the ".join(changed)
    return CommandResult.failure(
        ErrorCode.CHANGED_SINCE_VALIDATION,
        f"the {what} changed since this move was validated (another client may have changed "
        f"{'them' if len(changed) > 1 else 'it'}): the move could go elsewhere than the goal validated, so nothing "
        "moved; validate it again, check the new goal, then move",
        changed=changed, in_force=now)
