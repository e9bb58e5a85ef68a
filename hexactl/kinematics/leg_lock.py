"""Leg-lock projection: the pose closest to a given one at which one leg has a given length.

In leg-lock mode one actuator is braked and the five others move; every commanded pose
must keep the locked leg at its length, a 5-dimensional surface l_N(pose) = L.
:func:`project_to_locked_leg` finds the point of that surface closest to a pose in the
metric

    d² = |δx|² + |δy|² + |δz|² + c²·(δroll² + δpitch² + δyaw²)   (mm; angles in rad),

c = ``characteristic_length_mm`` (use ``Geometry.characteristic_length_mm``, the mean
platform-joint radius): a radian costs what the platform joints travel.

Method: the fixed-point iteration of the least-distance problem's optimality
conditions, x ← x₀ − λ·W⁻¹g, λ = (l_N(x) − L + g·(x₀ − x)) / (g·W⁻¹g), g = ∂l_N/∂pose at
the current iterate (twist-Jacobian row [u, (T·P_N) × u] mapped to Euler-angle rates),
W = diag(1, 1, 1, c², c², c²). Its fixed point is the true closest pose. It stops when the
locked leg's length is within the tolerance at an iterate the iteration produced (or at the
pose itself, which is then its own projection), or at the iteration cap (LinuxCNC
genhexkins style: bounded work, a status code instead of an exception). After
:data:`FIXED_POINT_ITERATIONS` without reaching the tolerance, Newton's steps on the same
fixed point take over: for corrections of hundreds of mm (the locked leg's length far
from the pose's) the plain iteration converges slowly or circles, and did not reach the
tolerance within the cap (found by the projection's property test).

Each step satisfies the constraint linearised at the iterate it starts from, so the length
error after it grows with the square of the distance between the two. From the pose itself
that distance is the whole correction: 30 mm off the surface needs four iterations to
reach 1e-9 mm. A pose that moves a little per cycle is tracked from a ``start`` next to
the answer (the pose corrected as the one a cycle ago was): two iterations, three at the
fastest motions, however far the pose is from the surface. That is how the controller's
loop uses it.

Plain-float Python on purpose, like :func:`hexactl.kinematics.inverse.leg_lengths`: it
needs one leg's row only and runs every cycle in leg-lock mode, where numpy's call
overhead on 3-vectors would dominate (BENCHMARKS.md, Kinematics, has the IK's figures).

Shared by the controller's leg-lock mode (hexactl.control) and leg-lock posture planning
(hexactl.calibration).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from math import cos, isfinite, pi, sin, sqrt

from hexactl.kinematics.axes import AbsoluteMmRad
from hexactl.kinematics.forward import solve_6x6
from hexactl.kinematics.inverse import LEG_COUNT, LegModel
from hexactl.kinematics.rotation import rotation_elements

PROJECTION_TOLERANCE_MM = 1e-9
"""Default: the locked leg's length error at which the projection stops, mm."""

PROJECTION_MAX_ITERATIONS = 50
"""Default iteration cap."""

FIXED_POINT_ITERATIONS = 20
"""Plain fixed-point iterations before Newton's steps take over: the loop's projections
(a start next to the answer) and corrections of tens of mm are done in a few; only
corrections of hundreds of mm, where the plain iteration crawls or circles, go on."""

_DIFFERENCE_STEP = 1e-6  # relative, for the Newton step's Jacobian by forward differences
_SMALLEST_NEWTON_FRACTION = 1.0 / 64  # the Newton step halved down to this before the plain step is taken

_MAX_PITCH_RAD = 0.45 * pi  # as in forward kinematics: beyond it the Euler chart is unusable
_NO_POSE = AbsoluteMmRad._make((float("nan"),) * 6)


_MAX_INPUT = 1e6
"""Pose coordinates (mm or rad) beyond this are refused as invalid: no platform is a
kilometre away, and squares of such numbers overflow the iteration."""


class ProjectionStatus(IntEnum):
    """Outcome of :func:`project_to_locked_leg`."""

    OK = 0
    MAX_ITERATIONS = 1  # tolerance not met within the iteration cap
    DIVERGED = 2  # the iterate left the valid chart (|pitch| ≥ 81°) or stopped being finite
    SINGULAR = 3  # the leg length does not depend on the pose (zero-length leg)
    INVALID_INPUT = 4  # leg outside 1–6, a non-finite, non-positive or absurdly large input, not six numbers


@dataclass(frozen=True, slots=True)
class ProjectionResult:
    """``pose``: absolute (mm, rad), trust it only when ``ok``. ``residual_mm``: the
    locked leg's length minus the target at ``pose``. ``correction``: the metric
    distance from the input pose, mm."""

    status: ProjectionStatus
    pose: AbsoluteMmRad
    iterations: int
    residual_mm: float
    correction: float

    @property
    def ok(self) -> bool:
        return self.status is ProjectionStatus.OK


def project_to_locked_leg(
    legs: LegModel,
    pose: Sequence[float],
    leg: int,
    length_mm: float,
    characteristic_length_mm: float,
    tolerance_mm: float = PROJECTION_TOLERANCE_MM,
    max_iterations: int = PROJECTION_MAX_ITERATIONS,
    start: Sequence[float] | None = None,
) -> ProjectionResult:
    """The pose closest to ``pose`` (absolute, mm and rad) at which leg ``leg`` (1–6) has
    joint-to-joint length ``length_mm``. ``start`` (absolute mm/rad): the first iterate,
    e.g. the projection of the pose a cycle ago; default ``pose``. From a ``start`` other
    than ``pose`` at least one iteration is made, since a start on the surface is the
    projection of another pose. Never raises; see :class:`ProjectionStatus`."""
    constraint = LockedLeg(legs, leg, length_mm, characteristic_length_mm, tolerance_mm)
    return constraint.project(pose, max_iterations, start)


class LockedLeg:
    """The constraint of :func:`project_to_locked_leg` (its arguments but the pose, the
    start and the iteration cap), checked and prepared once: a path is projected cycle
    after cycle onto the same one."""

    __slots__ = ("_valid", "_row", "_length_mm", "_characteristic_length_mm", "_angle_weight", "_tolerance_mm")

    def __init__(self, legs: LegModel, leg: int, length_mm: float, characteristic_length_mm: float,
                 tolerance_mm: float = PROJECTION_TOLERANCE_MM) -> None:
        try:
            self._valid = (1 <= leg <= LEG_COUNT and isfinite(length_mm) and length_mm > 0
                           and isfinite(characteristic_length_mm) and characteristic_length_mm > 0)
        except (TypeError, ValueError):
            self._valid = False
        self._row = legs.rows[leg - 1][:6] if self._valid else None  # P_N, B_N
        self._length_mm = length_mm
        self._characteristic_length_mm = characteristic_length_mm
        # W⁻¹ on angles
        self._angle_weight = 1.0 / (characteristic_length_mm * characteristic_length_mm) if self._valid else 0.0
        self._tolerance_mm = tolerance_mm

    def _toward(self, target: tuple[float, ...], q: tuple[float, ...]) -> tuple[float, tuple[float, ...] | None]:
        """At the iterate ``q``: the locked leg's length minus its target (mm), and the
        next iterate, the pose on the constraint linearised at ``q`` closest to ``target``
        (None: the length does not depend on the pose there, or its gradient overflowed)."""
        x0, y0, z0, roll0, pitch0, yaw0 = target
        x, y, z, roll, pitch, yaw = q
        px, py, pz, bx, by, bz = self._row
        angle_weight = self._angle_weight
        r11, r12, r13, r21, r22, r23, r31, r32, r33 = rotation_elements(roll, pitch, yaw)
        tx = r11 * px + r12 * py + r13 * pz  # T·P_N
        ty = r21 * px + r22 * py + r23 * pz
        tz = r31 * px + r32 * py + r33 * pz
        vx, vy, vz = tx + x - bx, ty + y - by, tz + z - bz
        current = sqrt(vx * vx + vy * vy + vz * vz)
        residual = current - self._length_mm
        if current < 1e-9:
            return residual, None
        ux, uy, uz = vx / current, vy / current, vz / current
        mx, my, mz = ty * uz - tz * uy, tz * ux - tx * uz, tx * uy - ty * ux  # (T·P_N) × u
        # ∂l/∂(roll, pitch, yaw) = m·∂ω/∂angle; ∂ω/∂roll = Rz·Ry·ex, ∂ω/∂pitch = Rz·ey, ∂ω/∂yaw = ez.
        g_roll = mx * r11 + my * r21 + mz * r31  # Rz·Ry·ex is T's first column
        sy, cy = sin(yaw), cos(yaw)
        g_pitch = -mx * sy + my * cy
        g_yaw = mz
        denominator = ux * ux + uy * uy + uz * uz + (g_roll * g_roll + g_pitch * g_pitch + g_yaw * g_yaw) * angle_weight
        if not 0.0 < denominator < float("inf"):  # overflowed: no gradient to follow
            return residual, None
        multiplier = (residual + ux * (x0 - x) + uy * (y0 - y) + uz * (z0 - z)
                      + g_roll * (roll0 - roll) + g_pitch * (pitch0 - pitch) + g_yaw * (yaw0 - yaw)) / denominator
        angle_step = multiplier * angle_weight
        return residual, (x0 - multiplier * ux, y0 - multiplier * uy, z0 - multiplier * uz,
                          roll0 - angle_step * g_roll, pitch0 - angle_step * g_pitch, yaw0 - angle_step * g_yaw)

    def _newton_step(self, target: tuple[float, ...], q: tuple[float, ...],
                     following: tuple[float, ...]) -> tuple[float, ...]:
        """Newton's step on the fixed point (the iterate where :meth:`_toward` stays put),
        from ``q`` whose next iterate is ``following``: its Jacobian by forward differences
        (six more steps), in mm and c·rad, the step halved while it does not bring the
        iteration closer to standing still. Where the plain iteration crawls or circles (a
        correction of a metre, the locked leg's length changed by hundreds of mm) this
        converges in a few steps."""
        scale = (1.0, 1.0, 1.0) + (self._characteristic_length_mm,) * 3
        moved = [(after - before) * unit for after, before, unit in zip(following, q, scale)]
        columns = []
        for axis in range(6):
            h = _DIFFERENCE_STEP * max(1.0, abs(q[axis]))
            nudged = tuple(value + h if k == axis else value for k, value in enumerate(q))
            after = self._toward(target, nudged)[1]
            if after is None:
                return following
            columns.append([((a - b) * unit - m) / h for a, b, unit, m in zip(after, nudged, scale, moved)])
        jacobian = [[columns[axis][row] for axis in range(6)] for row in range(6)]
        step = solve_6x6(jacobian, [-m for m in moved])
        if step is None:
            return following
        size = sum(m * m for m in moved)
        fraction = 1.0
        while fraction >= _SMALLEST_NEWTON_FRACTION:
            trial = tuple(value + fraction * d for value, d in zip(q, step))
            after = self._toward(target, trial)[1]
            if after is not None and sum(((a - b) * unit) ** 2 for a, b, unit in zip(after, trial, scale)) < size:
                return trial
            fraction /= 2
        return following

    def project(self, pose: Sequence[float], max_iterations: int = PROJECTION_MAX_ITERATIONS,
                start: Sequence[float] | None = None) -> ProjectionResult:
        """:func:`project_to_locked_leg` of ``pose`` from ``start`` onto this constraint."""
        try:
            target = tuple(map(float, pose))
            first = target if start is None else tuple(map(float, start))
            valid = (self._valid and len(target) == 6 and len(first) == 6
                     # map, not a generator: the loop projects every cycle. False for NaN too.
                     and all(map(_MAX_INPUT.__gt__, map(abs, target + first))))
        except (TypeError, ValueError):
            valid = False
        if not valid:
            return ProjectionResult(ProjectionStatus.INVALID_INPUT, _NO_POSE, 0, float("inf"), float("inf"))
        x0, y0, z0, roll0, pitch0, yaw0 = target
        tolerance_mm, characteristic_length_mm = self._tolerance_mm, self._characteristic_length_mm
        q = first
        iteration = 0
        min_iterations = 0 if first == target else 1
        while True:
            residual, following = self._toward(target, q)
            if abs(residual) <= tolerance_mm and iteration >= min_iterations:
                status = ProjectionStatus.OK
                break
            if iteration >= max_iterations:
                status = ProjectionStatus.MAX_ITERATIONS
                break
            if following is None:
                status = ProjectionStatus.SINGULAR
                break
            q = following if iteration < FIXED_POINT_ITERATIONS else self._newton_step(target, q, following)
            iteration += 1
            if not (abs(q[4]) < _MAX_PITCH_RAD and isfinite(sum(q))):
                return ProjectionResult(ProjectionStatus.DIVERGED, _NO_POSE, iteration, float("inf"), float("inf"))
        x, y, z, roll, pitch, yaw = q
        # Once, at the iterate it stops at: the iteration itself needs neither.
        correction = sqrt((x - x0) ** 2 + (y - y0) ** 2 + (z - z0) ** 2
                          + ((roll - roll0) ** 2 + (pitch - pitch0) ** 2 + (yaw - yaw0) ** 2)
                          * characteristic_length_mm * characteristic_length_mm)
        here = tuple.__new__(AbsoluteMmRad, (x, y, z, roll, pitch, yaw))  # no Python-level __new__
        return ProjectionResult(status, here, iteration, residual, correction)
