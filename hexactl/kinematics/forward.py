"""Forward kinematics: the pose from six leg lengths, by Newton–Raphson.

Like LinuxCNC's genhexkins: a pure function with an explicit tolerance, an iteration cap
and a status code. It never raises for numerical reasons and never returns a pose it did
not verify: the caller (the control loop) decides what a non-converged result means.

Each iteration solves J·[δR; δθ] = l_target − l(pose) with the analytic twist Jacobian
(rows [u_i, (T·P_mi) × u_i]) and maps the rotation increment δθ to Euler-angle
increments in closed form. Warm-started from the previous pose (the loop's case) it
converges in two or three iterations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from math import isfinite, pi

import numpy as np

from hexactl.kinematics.inverse import LegModel, twist_jacobian
from hexactl.kinematics.rotation import euler_rates_from_angular_velocity

FK_TOLERANCE_MM = 1e-9
"""Default convergence tolerance: the largest leg-length residual, mm."""

FK_MAX_ITERATIONS = 20
"""Default iteration cap."""

_MAX_PITCH_RAD = 0.45 * pi  # beyond ±81° the Euler update is ill-defined: call it divergence
_NO_POSE = (float("nan"),) * 6  # returned where no iterate is meaningful


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
    pose: tuple[float, float, float, float, float, float]
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
    pose = np.array(guess, dtype=float)
    target = np.array(lengths_mm, dtype=float)
    if pose.shape != (6,) or target.shape != (6,) or not (np.all(np.isfinite(pose)) and np.all(np.isfinite(target))):
        return FkResult(FkStatus.INVALID_INPUT, _NO_POSE, 0, float("inf"))

    jacobian, lengths = twist_jacobian(model, pose)
    residual = target - lengths
    worst = float(np.max(np.abs(residual)))
    first = worst
    for iteration in range(1, max_iterations + 1):
        if worst <= tolerance_mm:
            return FkResult(FkStatus.OK, _as_tuple(pose), iteration - 1, worst)
        try:
            step = np.linalg.solve(jacobian, residual)
        except np.linalg.LinAlgError:
            return FkResult(FkStatus.SINGULAR, _as_tuple(pose), iteration - 1, worst)
        pose[:3] += step[:3]
        pose[3:] += euler_rates_from_angular_velocity(step[3:], pose[4], pose[5])
        if not (abs(pose[4]) < _MAX_PITCH_RAD and all(isfinite(v) for v in pose)):
            return FkResult(FkStatus.DIVERGED, _NO_POSE, iteration, float("inf"))
        jacobian, lengths = twist_jacobian(model, pose)
        residual = target - lengths
        worst = float(np.max(np.abs(residual)))
        if worst > 1e3 * max(first, 1.0):
            return FkResult(FkStatus.DIVERGED, _as_tuple(pose), iteration, worst)
    if worst <= tolerance_mm:
        return FkResult(FkStatus.OK, _as_tuple(pose), max_iterations, worst)
    return FkResult(FkStatus.MAX_ITERATIONS, _as_tuple(pose), max_iterations, worst)


def _as_tuple(pose: np.ndarray) -> tuple[float, float, float, float, float, float]:
    x, y, z, roll, pitch, yaw = (float(v) for v in pose)
    return (x, y, z, roll, pitch, yaw)
