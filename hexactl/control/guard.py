"""The set-point guard: the last thing between the loop's arithmetic and the actuators.

Whatever the trajectory, the kinematics or a calibration swap produce, a set-point
that leaves the guard is inside the stroke and within ``max_step_mm`` of the previous
one (``leg_velocity_mm_s × period``). A guard that had to change anything reports
which legs: the plan upstream was wrong, and the loop counts it.

Plain-float Python on purpose: it runs every cycle on six values, where numpy's
per-call overhead would cost more than the arithmetic (see
:mod:`hexactl.kinematics.inverse`).
"""

from __future__ import annotations

from collections.abc import Sequence


def guard_setpoints(
    desired: Sequence[float],
    previous: Sequence[float],
    stroke_mm: tuple[float, float],
    max_step_mm: float,
) -> tuple[list[float], int]:
    """Limit ``desired`` (sensor mm) to the stroke and to ``max_step_mm`` from ``previous``.

    A non-finite desired value holds the previous one. Returns the set-points and a bit
    mask of the legs that were changed (bit i for leg i + 1; 0 when none was).

    ``previous`` must lie inside the stroke (the loop guarantees it: it only enables
    actuators that are inside, and every later value comes from here); then the
    result satisfies both limits exactly.
    """
    low, high = stroke_mm
    out = []
    clamped = 0
    for i, value in enumerate(desired):
        before = previous[i]
        if not low <= value <= high:  # also catches NaN
            value = before if value != value else (low if value < low else high)
            clamped |= 1 << i
        if value - before > max_step_mm:
            value = before + max_step_mm
            clamped |= 1 << i
        elif before - value > max_step_mm:
            value = before - max_step_mm
            clamped |= 1 << i
        out.append(value)
    return out, clamped
