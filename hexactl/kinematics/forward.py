"""Forward kinematics: the pose from six leg lengths, by Newton–Raphson.

Like LinuxCNC's genhexkins: a pure function with an explicit tolerance, an iteration cap
and a status code. It never raises for numerical reasons and never returns a pose it did
not verify: the caller (the control loop) decides what a non-converged result means.

Each iteration solves J·[δR; δθ] = l_target − l(pose) with the analytic twist Jacobian
(rows [u_i, (T·P_mi) × u_i]) and maps the rotation increment δθ to Euler-angle
increments in closed form. Warm-started from the previous pose (the loop's case) it
converges in two or three iterations.

Converged means the leg lengths are met, not that the pose is the platform's: near a
singular configuration other poses (another assembly mode) have almost the same
lengths, and Newton–Raphson lands on whichever is nearest its start. Callers that report
a pose to a person check the Jacobian condition there
(:func:`hexactl.kinematics.workspace.jacobian_condition`; ``hexactl fk`` does).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from math import isfinite, pi

from hexactl.kinematics.axes import AbsoluteMmRad
from hexactl.kinematics.inverse import LegModel, leg_jacobian_rows
from hexactl.kinematics.rotation import euler_rates_from_angular_velocity

FK_TOLERANCE_MM = 1e-9
"""Default convergence tolerance: the largest leg-length residual, mm."""

FK_MAX_ITERATIONS = 20
"""Default iteration cap."""

_MAX_PITCH_RAD = 0.45 * pi  # beyond ±81° the Euler update is ill-defined: call it divergence
_NO_POSE = (float("nan"),) * 6  # returned where no iterate is meaningful
_SINGULAR_PIVOT = 1e-12  # pivots below this fraction of the largest entry mean "singular"


class FkStatus(IntEnum):
    """Outcome of :func:`forward_kinematics`."""

    OK = 0
    MAX_ITERATIONS = 1  # ran out of iterations before the tolerance was met
    DIVERGED = 2  # residual grew without bound, or the pose left the valid chart
    SINGULAR = 3  # the Jacobian is singular at an iterate
    INVALID_INPUT = 4  # a length or the initial guess is not a finite number


@dataclass(frozen=True, slots=True)
class FkResult:
    """``pose`` is absolute (mm, rad) and is the last iterate; trust it only when ``ok``."""

    status: FkStatus
    pose: AbsoluteMmRad
    iterations: int
    residual_mm: float  # largest |l_target − l(pose)| at ``pose``

    @property
    def ok(self) -> bool:
        return self.status is FkStatus.OK


def forward_kinematics(
    model: LegModel,
    lengths_mm: Sequence[float],
    guess: Sequence[float],
    tolerance_mm: float = FK_TOLERANCE_MM,
    max_iterations: int = FK_MAX_ITERATIONS,
) -> FkResult:
    """Pose (absolute, mm and rad) whose leg lengths equal ``lengths_mm``.

    ``guess`` is the starting pose, normally the previous solution. Returns an
    :class:`FkResult`; its status says whether the pose can be trusted.
    """
    try:
        pose = [float(v) for v in guess]
        target = [float(v) for v in lengths_mm]
    except (TypeError, ValueError):
        return FkResult(FkStatus.INVALID_INPUT, _NO_POSE, 0, float("inf"))
    if len(pose) != 6 or len(target) != 6 or not all(isfinite(v) for v in (*pose, *target)):
        return FkResult(FkStatus.INVALID_INPUT, _NO_POSE, 0, float("inf"))

    rows, lengths = leg_jacobian_rows(model, pose)
    residual = [t - length for t, length in zip(target, lengths)]
    worst = max(abs(r) for r in residual)
    first = worst
    for iteration in range(1, max_iterations + 1):
        if worst <= tolerance_mm:
            return FkResult(FkStatus.OK, _absolute(pose), iteration - 1, worst)
        step = solve_6x6(rows, residual)
        if step is None:
            return FkResult(FkStatus.SINGULAR, _absolute(pose), iteration - 1, worst)
        roll_step, pitch_step, yaw_step = euler_rates_from_angular_velocity(step[3:], pose[4], pose[5])
        pose = [pose[0] + step[0], pose[1] + step[1], pose[2] + step[2],
                pose[3] + roll_step, pose[4] + pitch_step, pose[5] + yaw_step]
        if not (abs(pose[4]) < _MAX_PITCH_RAD and all(isfinite(v) for v in pose)):
            return FkResult(FkStatus.DIVERGED, _NO_POSE, iteration, float("inf"))
        rows, lengths = leg_jacobian_rows(model, pose)
        residual = [t - length for t, length in zip(target, lengths)]
        worst = max(abs(r) for r in residual)
        if worst > 1e3 * max(first, 1.0):
            return FkResult(FkStatus.DIVERGED, _absolute(pose), iteration, worst)
    if worst <= tolerance_mm:
        return FkResult(FkStatus.OK, _absolute(pose), max_iterations, worst)
    return FkResult(FkStatus.MAX_ITERATIONS, _absolute(pose), max_iterations, worst)


def solve_6x6(matrix: list[list[float]], rhs: list[float]) -> list[float] | None:
    """Solve A·x = b by Gaussian elimination with partial pivoting; None if A is singular.

    Hand-written because at 6×6 numpy.linalg.solve spends most of its time on call
    overhead and array creation (see BENCHMARKS.md). ``matrix`` and ``rhs`` are not modified.
    """
    n = len(rhs)
    a = [row[:] + [value] for row, value in zip(matrix, rhs)]
    scale = max(abs(v) for row in matrix for v in row)
    if not scale > 0.0:
        return None
    for col in range(n):
        pivot_row = max(range(col, n), key=lambda r: abs(a[r][col]))
        pivot = a[pivot_row][col]
        if abs(pivot) <= _SINGULAR_PIVOT * scale:
            return None
        a[col], a[pivot_row] = a[pivot_row], a[col]
        pivot_values = a[col]
        for r in range(col + 1, n):
            factor = a[r][col] / pivot
            if factor:
                row = a[r]
                for c in range(col, n + 1):
                    row[c] -= factor * pivot_values[c]
    x = [0.0] * n
    for r in range(n - 1, -1, -1):
        row = a[r]
        x[r] = (row[n] - sum(row[c] * x[c] for c in range(r + 1, n))) / row[r]
    return x


def _absolute(pose: Sequence[float]) -> AbsoluteMmRad:
    return tuple.__new__(AbsoluteMmRad, pose)  # the loop solves FK often: no _make call
