"""Carrying out a calibration campaign on a controller: the pure part.

:func:`hexactl.sim.offline_campaign.plan_campaign` plans which postures to measure; this
module decides in what order and along which path the controller visits them, and
turns measured feature points into achieved poses:

* :func:`campaign_postures`: each leg's postures in a short travel order
  (:func:`travel_order`). The D-optimal picks lie all over the pose envelope; visiting
  them in the planner's order roughly doubles the travel, hence the time.
* :func:`locked_path`: the waypoints of a leg-lock move. A move is a straight line in
  pose space; the controller's loop keeps the locked leg's length by projecting each
  cycle's target onto its constraint, warm-started from the cycle before, with at most
  ``ControllerConfig.lock_cycle_iterations`` iterations; planning refuses a move
  (``lock_unreachable``) if that would not converge at one of its cycles. Between
  postures far apart the line strays up to ~180 mm from the constraint, and at the
  demo's motion limits planning refuses some of those moves (from ~150 mm on; it
  depends on the speed too). Such a move is split at points on the constraint until no
  chord strays more than :data:`LOCKED_CHORD_TOLERANCE_MM` (the campaign runner sends a
  move straight first and splits only one the controller refuses).
* :func:`achieved_pose`: the pose relative to the zero posture of measured points.

Poses relative to the zero posture are in mm and degrees, as everywhere at the edges.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.planning import DEFAULT_CANDIDATES, PlanRequest, PosturePlan, plan_postures
from hexactl.calibration.validation import ValidationSummary
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LEG_COUNT, leg_lengths_batch
from hexactl.kinematics.leg_lock import project_to_locked_leg
from hexactl.kinematics.points import pose_from_points
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute

LOCKED_CHORD_TOLERANCE_MM = 10.0
"""How far (locked leg's length error, mm) a piece of a leg-lock move may stray from the
constraint. A wide margin rather than the controller's limit: planning refused none of the
pieces it leaves on the demo's plans (seeds 0–5) and the default plan (seeds 0–2) as
``lock_unreachable``, whereas it refuses some unsplit moves straying ~150 mm at the demo's
speeds. It dates from when the loop projected each cycle from the target itself, which
converged from ~20 mm only; every piece is one more stop, which is why the campaign splits
only the moves the controller refuses."""

_CHORD_SAMPLES = 17  # points checked along each chord, ends included
_MAX_SPLIT_DEPTH = 8  # at most 2⁸ pieces per move: far more than any posture pair needs

SENSOR_SIGMA_MM = 0.001
"""Default noise of the simulated length sensors, 1σ, mm (a µm-resolution sensor)."""


@dataclass(frozen=True, slots=True)
class CampaignDesign:
    """The campaign's protocol: ``postures_per_leg`` leg-lock postures for each leg (0: none)
    and ``free_postures`` with no leg locked, planned from ``candidates`` random poses in
    ``envelope_fraction`` of the pose envelope (:class:`~hexactl.calibration.planning.PlanRequest`);
    noise of the simulated sensors and instrument (None: the geometry's ``point_sigma_mm``);
    one ``seed`` for planning and noise."""

    postures_per_leg: int = 20
    free_postures: int = 0
    candidates: int = DEFAULT_CANDIDATES
    envelope_fraction: float = 1.0
    sensor_sigma_mm: float = SENSOR_SIGMA_MM
    point_sigma_mm: float | None = None
    seed: int = 0


def plan_campaign(controller: Geometry, design: CampaignDesign) -> tuple[PosturePlan, ...]:
    """Leg-lock plans for legs 1–6 then the free plan, on the controller's geometry.

    Raises ``ValueError`` if a plan fails (its message says why).
    """
    # One candidate stream per plan (leg 0: free), distinct for every seed and leg.
    requests = [PlanRequest(leg, design.postures_per_leg, candidates=design.candidates, seed=10 * design.seed + leg,
                            envelope_fraction=design.envelope_fraction)
                for leg in range(1, LEG_COUNT + 1) if design.postures_per_leg]
    if design.free_postures:
        requests.append(PlanRequest(0, design.free_postures, candidates=design.candidates, seed=10 * design.seed,
                                    envelope_fraction=design.envelope_fraction))
    plans = tuple(plan_postures(controller, request) for request in requests)
    for plan in plans:
        if not plan.ok:
            raise ValueError(f"planning leg {plan.leg}: {plan.message}")
    return plans


@dataclass(frozen=True, slots=True)
class CampaignPosture:
    """One posture to measure: ``leg`` (1–6) locked, at ``pose`` (relative mm/deg)."""

    leg: int
    pose: tuple[float, float, float, float, float, float]


def travel_order(poses: NDArray, characteristic_length_mm: float, start: Sequence[float] = (0.0,) * 6) -> list[int]:
    """Indices of ``poses`` (N, 6 relative mm/deg) in nearest-neighbour order from ``start``.

    Distance: |δposition|² + c²·|δangles in rad|², c = ``characteristic_length_mm`` (a
    radian costs what the platform joints travel, the leg-lock projection's metric).
    Greedy, not an optimal tour: within 25 % of one for points like these, and instant.
    """
    weights = np.array([1.0, 1.0, 1.0] + [characteristic_length_mm * np.pi / 180.0] * 3)
    scaled = np.asarray(poses, dtype=float) * weights
    here = np.asarray(start, dtype=float) * weights
    left = list(range(len(scaled)))
    order = []
    while left:
        nearest = left[int(np.argmin(np.linalg.norm(scaled[left] - here, axis=1)))]
        left.remove(nearest)
        order.append(nearest)
        here = scaled[nearest]
    return order


def campaign_postures(plans: Sequence[PosturePlan], characteristic_length_mm: float) -> tuple[CampaignPosture, ...]:
    """The leg-lock plans' postures in visiting order: plan by plan (each starts and ends
    at the zero posture, where the leg is locked), each plan's in :func:`travel_order`.

    Raises ``ValueError`` for a free-posture plan (leg 0): a campaign locks a leg.
    """
    postures = []
    for plan in plans:
        if not 1 <= plan.leg <= 6:
            raise ValueError(f"a campaign plan locks a leg 1-6, got leg {plan.leg}")
        for index in travel_order(plan.poses_relative, characteristic_length_mm):
            x, y, z, roll, pitch, yaw = (float(v) for v in plan.poses_relative[index])
            postures.append(CampaignPosture(plan.leg, (x, y, z, roll, pitch, yaw)))
    return tuple(postures)


def locked_path(geometry: Geometry, leg: int, length_mm: float, start: Sequence[float], goal: Sequence[float],
                tolerance_mm: float = LOCKED_CHORD_TOLERANCE_MM) -> list[tuple[float, ...]]:
    """Waypoints (relative mm/deg) from ``start`` to ``goal`` with leg ``leg`` locked at
    joint-to-joint ``length_mm`` on ``geometry``; the last one is ``goal``.

    Both ends should lie on the constraint (the controller projects them anyway). A
    chord whose locked-leg length strays more than ``tolerance_mm`` from ``length_mm`` is
    split at its midpoint projected onto the constraint, recursively.
    Raises ``ValueError`` if a midpoint cannot be projected.
    """
    start_pose, goal_pose = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    fractions = np.linspace(0.0, 1.0, _CHORD_SAMPLES)[:, None]

    def split(a: NDArray, b: NDArray, depth: int) -> list[NDArray]:
        chord = absolute_from_relative(geometry.home, a + (b - a) * fractions)
        stray = np.max(np.abs(leg_lengths_batch(geometry.legs, chord)[:, leg - 1] - length_mm))
        if stray <= tolerance_mm or depth >= _MAX_SPLIT_DEPTH:
            return [b]
        middle = project_to_locked_leg(geometry.legs, absolute_from_relative(geometry.home, (a + b) / 2), leg,
                                       length_mm, geometry.characteristic_length_mm)
        if not middle.ok:
            raise ValueError(f"leg {leg} locked at {length_mm:.3f} mm: no pose on the constraint between "
                             f"{np.round(a, 3).tolist()} and {np.round(b, 3).tolist()} ({middle.status.name.lower()})")
        m = relative_from_absolute(geometry.home, middle.pose)
        return split(a, m, depth + 1) + split(m, b, depth + 1)

    return [tuple(float(v) for v in pose) for pose in split(start_pose, goal_pose, 0)]


def achieved_pose(geometry: Geometry, points_mm: NDArray) -> NDArray[np.float64]:
    """The pose relative to ``geometry``'s zero posture (mm, deg) that measured feature
    points (K, 3, fixed frame, mm; the first K of ``[measurement] feature_points``) show.

    Raises :class:`~hexactl.kinematics.points.DegeneratePointsError` for collinear points.
    """
    points = np.asarray(points_mm, dtype=float)
    model = np.array(geometry.measurement.feature_points, dtype=float)[: len(points)]
    return relative_from_absolute(geometry.home, np.array(pose_from_points(model, points).pose))


def improved(before: ValidationSummary, after: ValidationSummary) -> bool:
    """Whether a calibration made the platform more accurate: both the largest position
    and the largest orientation error over the test motions went down."""
    return (after.max_position_error_mm < before.max_position_error_mm
            and after.max_orientation_error_deg < before.max_orientation_error_deg)
