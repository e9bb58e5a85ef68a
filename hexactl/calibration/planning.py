"""Planning calibration postures: feasible, inside every limit with margin, informative.

Candidates are sampled in the pose envelope, projected onto the locked leg's constraint
surface (:func:`~hexactl.kinematics.leg_lock.project_to_locked_leg`), checked with
:func:`~hexactl.kinematics.workspace.assess_poses` plus margins (the real platform differs
from the planning geometry by millimetres), and the requested number is chosen greedily
for D-optimality: each pick maximises the determinant of the Fisher information of the
42 structural parameters (:mod:`hexactl.calibration.uncertainty`), i.e. it shrinks the
volume of the parameters' confidence ellipsoid the most.

The information is that of the ``full`` identification, which every posture feeds with
all six legs; a locked leg's own seven parameters are part of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.leg_lock import project_to_locked_leg
from hexactl.calibration.uncertainty import DEFAULT_READING_SIGMA_MM, posture_information_factors
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LEG_COUNT, leg_lengths, readings_from_lengths, sensor_setpoints_batch
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute
from hexactl.kinematics.workspace import PoseAssessment, assess_poses

DEFAULT_CANDIDATES = 1500

MAX_CANDIDATES = 100_000
"""More would take gigabytes of memory (about 5 kB a candidate) for no information worth it."""


@dataclass(frozen=True, slots=True)
class PlanMargins:
    """How far inside each limit a planned posture must stay.

    Stroke and pose-envelope margins in mm (deg for the envelope's angles), joint cones in
    deg; ``condition_fraction`` scales the geometry's near-singularity threshold.
    """

    stroke_mm: float = 10.0
    cone_deg: float = 2.0
    envelope_mm: float = 10.0
    envelope_deg: float = 1.0
    condition_fraction: float = 0.8

    def accepts(self, geometry: Geometry, assessment: PoseAssessment) -> bool:
        limits = geometry.limits
        envelope = np.array([self.envelope_mm] * 3 + [self.envelope_deg] * 3)
        return (
            assessment.ok
            and min(assessment.stroke_margin_mm) >= self.stroke_mm
            and max(assessment.base_cone_deg) <= limits.base_cone_deg - self.cone_deg
            and max(assessment.platform_cone_deg) <= limits.platform_cone_deg - self.cone_deg
            and bool(np.all(np.array(assessment.pose_margin) >= envelope))
            and assessment.jacobian_condition <= self.condition_fraction * limits.max_jacobian_condition
        )


@dataclass(frozen=True, slots=True)
class PlanRequest:
    """What to plan.

    ``leg`` 1–6 is locked at ``locked_length_mm`` (joint-to-joint, mm; None: its length in
    the zero posture, where every leg reads mid-stroke-ish and stays far from its limits);
    ``leg`` 0 plans free postures. ``count`` postures are chosen from ``candidates``
    random ones (seeded), drawn in the pose envelope (inside the margins) scaled about the
    zero posture by ``envelope_fraction`` (0, 1] before the leg-lock projection: less than
    1 trades information for shorter moves between postures. Noise figures weight the information (None: the
    geometry's).
    """

    leg: int
    count: int
    locked_length_mm: float | None = None
    candidates: int = DEFAULT_CANDIDATES
    seed: int = 0
    margins: PlanMargins = field(default_factory=PlanMargins)
    point_sigma_mm: float | None = None
    reading_sigma_mm: float = DEFAULT_READING_SIGMA_MM
    envelope_fraction: float = 1.0


class PlanStatus(IntEnum):
    OK = 0
    TOO_FEW_FEASIBLE = 1  # fewer feasible candidates than requested postures
    INVALID_REQUEST = 2  # leg or count out of range, or a non-positive locked length


@dataclass(frozen=True, slots=True, eq=False)
class PosturePlan:
    """Planned postures: ``poses_relative`` (M, 6) mm/deg from the zero posture, with the
    sensor set-points ``setpoints_mm`` (M, 6) on the planning geometry. ``locked_length_mm``
    and ``locked_reading_mm`` are NaN for free postures."""

    status: PlanStatus
    leg: int
    poses_relative: NDArray[np.float64]
    setpoints_mm: NDArray[np.float64]
    locked_length_mm: float
    locked_reading_mm: float
    feasible_candidates: int
    message: str

    @property
    def ok(self) -> bool:
        return self.status is PlanStatus.OK


def _request_problems(request: PlanRequest) -> list[str]:
    """What is wrong with ``request``, each with what to give instead (empty: nothing)."""
    problems = []
    if not 0 <= request.leg <= LEG_COUNT:
        problems.append(f"leg {request.leg} is not a leg: give 1 to {LEG_COUNT}, or 0 for free postures")
    if request.count < 1:
        problems.append(f"count {request.count}: plan at least 1 posture")
    elif request.candidates < request.count:
        problems.append(f"{request.candidates} candidates cannot give {request.count} postures: give at least "
                        f"{request.count} candidates (more give a better-conditioned plan)")
    if request.candidates > MAX_CANDIDATES:
        problems.append(f"{request.candidates} candidates: give at most {MAX_CANDIDATES}")
    if not 0 < request.envelope_fraction <= 1:
        problems.append(f"envelope fraction {request.envelope_fraction} is not in (0, 1]")
    return problems


def plan_postures(geometry: Geometry, request: PlanRequest) -> PosturePlan:
    """Plan ``request.count`` leg-lock (or free) postures on ``geometry``; see the module docstring.

    Every returned posture satisfies the lock to 1e-9 mm on ``geometry`` and passes
    :func:`assess_poses` with ``request.margins``. Never raises for bad requests: the
    status says what went wrong and ``message`` explains it.
    """
    nan = float("nan")
    empty = np.zeros((0, 6))
    if problems := _request_problems(request):
        return PosturePlan(PlanStatus.INVALID_REQUEST, request.leg, empty, empty, nan, nan, 0, "; ".join(problems))
    home = np.array(geometry.home.in_radians())
    locked_length = nan
    if request.leg:
        locked_length = (
            leg_lengths(geometry.legs, home)[request.leg - 1] if request.locked_length_mm is None else request.locked_length_mm
        )
        if not locked_length > 0:
            return PosturePlan(PlanStatus.INVALID_REQUEST, request.leg, empty, empty, nan, nan, 0,
                f"locked length must be positive, got {locked_length}")
    candidates = _feasible_candidates(geometry, request, locked_length)
    locked_reading = float(readings_from_lengths(geometry.legs, locked_length, request.leg - 1)) if request.leg else nan
    if len(candidates) < request.count:
        low, high = geometry.limits.stroke
        margin = request.margins.stroke_mm
        # A locked reading inside the stroke's margin leaves no posture at all: more candidates cannot help.
        remedy = (f"the locked reading {locked_reading:.3f} mm lies within the stroke's {margin:g} mm margin "
                  f"([{low:g}, {high:g}] mm): lock the leg between {low + margin:g} and {high - margin:g} mm"
                  if request.leg and not low + margin <= locked_reading <= high - margin else
                  f"raise --candidates (at most {MAX_CANDIDATES})" + (" or choose another locked length" if request.leg
                                                                     else ""))
        return PosturePlan(PlanStatus.TOO_FEW_FEASIBLE, request.leg, empty, empty, locked_length, locked_reading,
            len(candidates), f"only {len(candidates)} of {request.candidates} candidates are feasible with the "
            f"margins, {request.count} requested: {remedy}")
    sigma = geometry.measurement.point_sigma_mm if request.point_sigma_mm is None else request.point_sigma_mm
    factors = posture_information_factors(
        geometry.legs, absolute_from_relative(geometry.home, candidates),
        np.array(geometry.measurement.feature_points), sigma, request.reading_sigma_mm)
    chosen = greedy_d_optimal(factors, request.count)
    poses = candidates[chosen]
    setpoints = sensor_setpoints_batch(geometry.legs, absolute_from_relative(geometry.home, poses))
    what = f"leg {request.leg} locked at {locked_length:.3f} mm (reading {locked_reading:.3f} mm)" if request.leg else "free postures"
    return PosturePlan(PlanStatus.OK, request.leg, poses, setpoints, locked_length, locked_reading, len(candidates),
        f"{request.count} postures, {what}, D-optimal from {len(candidates)} feasible of {request.candidates} candidates")


def _feasible_candidates(geometry: Geometry, request: PlanRequest, locked_length: float) -> NDArray[np.float64]:
    """Random relative poses (mm, deg) that satisfy the lock and the margins."""
    rng = np.random.default_rng(request.seed)
    margins = request.margins
    inset = np.array([margins.envelope_mm] * 3 + [margins.envelope_deg] * 3)
    fraction = request.envelope_fraction
    low, high = fraction * (np.array(geometry.limits.pose_min) + inset), fraction * (np.array(geometry.limits.pose_max) - inset)
    # Uniform in the box puts most samples in its corners, where joint cones and strokes
    # run out; a random radial scale keeps the interior and the single-axis extremes covered.
    samples = rng.uniform(low, high, size=(request.candidates, 6)) * rng.uniform(0.2, 1.0, size=(request.candidates, 1))
    if request.leg:
        projected = []
        for relative in samples:
            result = project_to_locked_leg(geometry.legs, absolute_from_relative(geometry.home, relative),
                                           request.leg, locked_length, geometry.characteristic_length_mm)
            if result.ok:
                projected.append(relative_from_absolute(geometry.home, result.pose))
        samples = np.array(projected).reshape(-1, 6)
    assessments = assess_poses(geometry, samples)
    keep = [margins.accepts(geometry, assessment) for assessment in assessments]
    return samples[np.array(keep, dtype=bool)]


def greedy_d_optimal(factors: NDArray, count: int) -> list[int]:
    """Indices of ``count`` candidates chosen one by one to maximise det(Σ F_jᵀF_j).

    ``factors`` (C, r, p) are the candidates' information square roots. Each step takes
    the candidate with the largest log det(I + F_c·I⁻¹·F_cᵀ), the determinant gain by the
    matrix determinant lemma. A small ridge (1e-9 of the mean information's trace) starts
    the recursion before the information has full rank; candidates are not repeated.
    """
    factors = np.asarray(factors, dtype=float)
    size = factors.shape[2]
    mean_trace = float(np.einsum("crp,crp->", factors, factors)) / len(factors)
    information = 1e-9 * mean_trace / size * np.eye(size)
    available = np.ones(len(factors), dtype=bool)
    chosen: list[int] = []
    identity = np.eye(factors.shape[1])
    for _ in range(count):
        inverse = np.linalg.inv(information)
        gain_matrices = identity + (factors @ inverse) @ np.transpose(factors, (0, 2, 1))
        gains = np.linalg.slogdet(gain_matrices)[1]
        gains[~available] = -np.inf
        best = int(np.argmax(gains))
        chosen.append(best)
        available[best] = False
        information = information + factors[best].T @ factors[best]
    return chosen
