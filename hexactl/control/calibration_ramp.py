"""The ramp from the old set-points to the new geometry's after a calibration swap.

Swapping the geometry while ENABLED would step the set-points by the difference the
new model makes at the commanded pose. Instead :class:`CalibrationRamp` takes that
difference (the set-points being sent minus the new geometry's at the pose) and fades
it out linearly, all legs together, at ``fraction`` of the new geometry's leg velocity
limit (moves are planned within the rest of it), while the commanded pose carries on.
The controller checks beforehand that every pose the ramp passes through is within the
limits (:func:`~hexactl.control.calibration_checks.swap_refusal`).

Set-points: sensor mm. Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Sequence

from hexactl.control.planning import ActiveGeometry


class CalibrationRamp:
    """The offset still to fade out, for a loop running every ``period_s``."""

    def __init__(self, fraction: float, period_s: float) -> None:
        self._fraction = fraction
        self._period_s = period_s
        self._offset: list[float] | None = None  # per leg, mm, at full weight
        self._left = 0.0  # the weight still applied, 1 → 0
        self._decrement = 0.0  # per cycle

    @property
    def active(self) -> bool:
        return self._offset is not None

    def begin(self, sent: Sequence[float], new: ActiveGeometry, pose: Sequence[float]) -> None:
        """Ramp from ``sent`` (the set-points being sent) to ``new``'s set-points at
        ``pose`` (relative mm/rad); replaces a ramp under way (``sent`` includes it).
        Nothing to ramp when they are equal."""
        offset = [s - t for s, t in zip(sent, new.setpoints_at(pose))]
        largest = max(abs(o) for o in offset)
        if largest > 0.0:
            step_mm = self._fraction * new.geometry.limits.leg_velocity_mm_s * self._period_s
            self._offset, self._left, self._decrement = offset, 1.0, step_mm / largest
        else:
            self._offset = None

    def apply(self, desired: list[float]) -> list[float]:
        """This cycle's set-points: ``desired`` (the new geometry's) plus what is left of
        the offset; one cycle of the ramp passes."""
        offset = self._offset
        if offset is None:
            return desired
        left = self._left
        self._left = left - self._decrement
        if self._left <= 0.0:
            self._offset = None
        return [d + left * o for d, o in zip(desired, offset)]

    def cancel(self) -> None:
        """Forget the ramp (the motion is frozen: the set-points stay as they are)."""
        self._offset = None
