"""The platform's measured pose: forward kinematics of the actuators' feedback.

:class:`PoseMeasurement` solves FK warm-started from its last solution (from the
commanded pose when it has none), so that one or two iterations usually do; when that
fails, once more from the zero posture. The core measures every cycle while not ENABLED
and every ``every_cycles`` cycles while ENABLED (``fk_rate_hz``), plus at each dwell's
record.

Poses: ``pose`` relative to the active geometry's zero posture, mm and rad (None when
FK failed or never ran, or a leg has no reading yet). Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import isfinite

from hexactl.control.hardware import FeedbackSnapshot
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.axes import AbsoluteMmRad, RelativeMmRad
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.inverse import lengths_from_readings


class PoseMeasurement:
    """FK of the feedback at most every ``every_cycles`` cycles (when asked with :meth:`due`),
    to ``tolerance_mm`` within ``max_iterations``."""

    def __init__(self, every_cycles: int, tolerance_mm: float, max_iterations: int) -> None:
        self.every_cycles = every_cycles
        self._tolerance_mm = tolerance_mm
        self._max_iterations = max_iterations
        self.pose: RelativeMmRad | None = None
        self.failures = 0  # FK runs on readings of all six legs that did not converge
        self.cycle = 0  # the cycle it last ran in
        self._absolute: AbsoluteMmRad | None = None  # the last solution, absolute mm/rad: the warm start

    def due(self, cycle: int) -> bool:
        return cycle - self.cycle >= self.every_cycles

    def measure(self, cycle: int, feedback: FeedbackSnapshot, active: ActiveGeometry,
                commanded: Sequence[float]) -> None:
        """Solve FK of ``feedback`` on ``active`` in cycle ``cycle``; ``commanded`` (relative
        mm/rad) is the start when there is no previous solution."""
        self.cycle = cycle
        lengths = lengths_from_readings(active.geometry.legs, feedback.positions_mm).tolist()
        guess = self._absolute or active.absolute_from_relative_mm_rad(commanded)
        result = forward_kinematics(active.geometry.legs, lengths, guess, self._tolerance_mm, self._max_iterations)
        if not result.ok and guess != active.home:
            # A start far from the legs (a wild reading's solution, which the commanded pose
            # follows while disabled) may never converge again; from the zero posture it does
            # across the workspace.
            result = forward_kinematics(active.geometry.legs, lengths, active.home, self._tolerance_mm,
                                        self._max_iterations)
        if result.ok:
            self._absolute = result.pose
            self.pose = active.relative_from_absolute_mm_rad(result.pose)
        else:
            self._absolute = self.pose = None
            # A leg not read yet (the link's NaN before its first report) is no failure of FK,
            # which the count would report on every start. Checked here, off the hot path.
            if isfinite(sum(feedback.positions_mm)):
                self.failures += 1

    def geometry_changed(self) -> None:
        """Another model: start from the commanded pose and measure at the next :meth:`due`."""
        self._absolute = None
        self.cycle = -self.every_cycles
