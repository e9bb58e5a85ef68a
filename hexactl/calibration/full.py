"""``full``: every structural parameter from every posture, by maximum likelihood.

Errors-in-variables model. Unknowns: the 42 structural parameters θ (optionally six sensor
scale errors) and each posture's true pose (6 per posture); optionally, as nuisance
parameters after θ, each leg's offset drift d_i over the campaign (time τ_j from 0 at the
first row to 1 at the last) and the feature points p_k themselves. Observations and
residuals, each divided by its noise standard deviation:

- feature points: T_j·p_k + R_j − m_jk (σ = point_sigma_mm per coordinate, or whitened by
  each point's own covariance where an instrument's angles and ranges implied it:
  :mod:`hexactl.calibration.observations`);
- leg closure, all six legs, locked or free: ‖T_j·P_i + R_j − B_i‖ − zero_i − d_i·(τ_j − 1)
  − (1 + s_i)·l_ij (σ = reading_sigma_mm), so the zero lengths are the campaign's end;
- with feature points as parameters, their prior p_k − p_k⁰ (σ = feature_point_sigma_mm).

The result's covariance is the structural parameters' marginal (the nuisance block's
Schur complement), so their uncertainty carries that of the drift and the feature points;
where the residuals exceed the noise model, the feature points' and the readings' shares of
it are scaled up each by its own excess (:func:`_noise_scaled_covariance`).

Minimising their sum of squares is the maximum-likelihood estimate for Gaussian noise and
reaches the Cramér–Rao bound. The fixed frame is the instrument's and the moving frame the
feature points', so there is no gauge freedom and all 42 parameters are observable with
varied postures (the singular values in the result check it on the actual data).

Pose-form data (no points) are handled by the same model: the measured pose is turned into
the feature points it implies, which weights it exactly as a point fit would.

Gross errors, mis-sightings and wrong readings (a typo, a wrong column): after the fit, each
observation's standardised residual is tested, a feature point's 3-D residual (χ², 3 dof) or,
in pose form, a row's whole pose (χ², 6 dof), and each reading's leg closure (χ², 1 dof),
with its leverage taken out (its pull on its posture's pose and on the parameters) so an
observation the fit pulls toward itself is not hidden. Those beyond the cut that a campaign
without gross errors passes with probability 1 − ``exclusion_false_alarm`` (Bonferroni over
all observations, points and readings) are excluded, at most the worst one per posture per
round (a bad observation drags its posture's good ones along; the worst is the least
probable, and a pose-form row's pose, whose exclusion would drop the row, only once its
worst reading has been tried), and the fit repeated; an excluded observation drops out of
the fit as if it had not been measured (weight 0), and one the new fit predicts within the
cut comes back; until nothing changes. It stops and says so where exclusion would stop
being about isolated gross errors: more than :data:`MAX_EXCLUDED_FRACTION` of the postures
touched (the misfit is a model error, unless one observation carries
:data:`CONCENTRATED_MISFIT_SHARE` of it: a wrong reading drags its pose by tens of mm and
biases every posture, and it alone is excluded then), or parameters left undetermined.
Where the plain fit has an observation beyond the cut or did not converge, the rounds begin
instead from the observations a robust fit puts beyond it (:func:`_robust_start`), so that
gross errors in up to that share of the postures cannot bias the fit they are tested against.

Solver: Levenberg–Marquardt on the sparse problem by the Schur complement, as in bundle
adjustment. Each posture's 6×6 pose block is eliminated, leaving a p×p system; the reduced
normal matrix at the solution is the parameters' Fisher information, whose inverse is
their covariance. Pose updates are rotation vectors applied on the left, so the Euler
chart's singularities never enter the iteration. Cost: O(N·p²) per iteration.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hexactl.calibration.data import MeasurementData, measured_poses
from hexactl.calibration.jacobians import point_twist_jacobians
from hexactl.calibration.parameters import GEOMETRIC_PARAMETERS, PARAMETERS_PER_LEG, SCALE_UNIT, StructuralParameters
from hexactl.calibration.results import (
    MIN_POSTURES,
    Estimate,
    ExcludedObservation,
    IdentificationOptions,
    IdentificationResult,
    IdentificationStatus,
    Method,
    PostureResiduals,
    assemble_result,
    failed_result,
    flag_outliers,
)
from hexactl.calibration.uncertainty import analyse_information
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LEG_COUNT

_STEP_TOLERANCE_MM = 1e-9  # parameter and pose steps below this end the iteration
_COST_TOLERANCE = 1e-10  # relative cost decrease below this ends the iteration
_MAX_EXCLUSION_ROUNDS = 10
MAX_EXCLUDED_FRACTION = 0.1
"""Exclusion stops before it touches more than this share of the postures: the misfit is a
model error then, unless it is concentrated (:data:`CONCENTRATED_MISFIT_SHARE`)."""
CONCENTRATED_MISFIT_SHARE = 0.1
"""While observations beyond the cut touch more than :data:`MAX_EXCLUDED_FRACTION` of the
postures, the worst of all is still excluded, alone, if it carries at least this share of the
fit's χ²: a gross error that biases the whole fit, where a model error's misfit is spread thin."""


@dataclass(frozen=True, slots=True, eq=False)
class _Problem:
    """The fixed inputs: observed points (N, K, 3), their model (K, 3), readings (N, 6).

    ``times`` (N,) in [0, 1], the campaign's time of each posture, when the sensor offsets'
    drift is estimated (None: not); ``target_sigma`` > 0: the feature points are parameters
    too, with ``model_points`` as their prior mean and this standard deviation per
    coordinate (0: exactly known).
    """

    observed: NDArray[np.float64]
    model_points: NDArray[np.float64]
    readings: NDArray[np.float64]
    point_sigma: float
    reading_sigma: float
    with_scales: bool
    point_weights: NDArray[np.float64]  # (N, K): 1 used, 0 excluded
    reading_weights: NDArray[np.float64]  # (N, 6): 1 used, 0 excluded
    times: NDArray[np.float64] | None = None
    target_sigma: float = 0.0
    whitening: NDArray[np.float64] | None = None  # (N, K, 3, 3) L⁻¹ of each point's covariance L·Lᵀ; None: 1/σ

    def whiten(self, vectors: NDArray) -> NDArray[np.float64]:
        """Point-space vectors or Jacobians (N, K, 3, ...) divided by their noise."""
        if self.whitening is None:
            return vectors / self.point_sigma
        return np.einsum("nkij,nkj...->nki...", self.whitening, vectors)

    def in_mm(self, misfits: NDArray) -> NDArray[np.float64]:
        """Whitened point misfits (N, K, 3) back in mm."""
        if self.whitening is None:
            return misfits * self.point_sigma
        return np.linalg.solve(self.whitening, misfits[..., None])[..., 0]

    def observation_weights(self, pose_form: bool) -> NDArray[np.float64]:
        """(N, M) weights of the observations tested for gross errors, 1 used and 0 excluded:
        each posture's feature points (pose form: its pose, one observation), then its six
        readings."""
        observed = self.point_weights[:, :1] if pose_form else self.point_weights
        return np.concatenate((observed, self.reading_weights), axis=1)

    def with_observation_weights(self, weights: NDArray, pose_form: bool) -> _Problem:
        """The problem with :meth:`observation_weights` set to ``weights``."""
        observed = weights[:, :-LEG_COUNT]
        if pose_form:  # a pose-form row's points stand or fall together
            observed = np.repeat(observed, self.point_weights.shape[1], axis=1)
        return replace(self, point_weights=observed, reading_weights=weights[:, -LEG_COUNT:])

    def observation_dof(self, pose_form: bool) -> NDArray[np.float64]:
        """(M,): each tested observation's degrees of freedom, as in :meth:`observation_weights`."""
        observed = [6.0] if pose_form else [3.0] * self.point_weights.shape[1]
        return np.array(observed + [1.0] * LEG_COUNT)

    @property
    def structural_size(self) -> int:
        return GEOMETRIC_PARAMETERS + (LEG_COUNT if self.with_scales else 0)

    def split(self, theta: NDArray) -> tuple[NDArray, NDArray | None, NDArray | None]:
        """θ as (structural, drift (6,) or None, feature points (K, 3) or None): the layout
        ``[structural | drift | feature points]``, each part present only when estimated."""
        start = self.structural_size
        drift = None
        if self.times is not None:
            drift, start = theta[start : start + LEG_COUNT], start + LEG_COUNT
        targets = theta[start:].reshape(-1, 3) if self.target_sigma > 0.0 else None
        return theta[: self.structural_size], drift, targets


@dataclass(frozen=True, slots=True, eq=False)
class _Linearisation:
    point_misfits: NDArray[np.float64]  # (N, K, 3), whitened, excluded points included
    point_jacobian: NDArray[np.float64]  # (N, K, 3, 6), whitened, excluded points included
    point_residuals: NDArray[np.float64]  # (N, K, 3), whitened, excluded points zero
    leg_misfits: NDArray[np.float64]  # (N, 6), whitened, excluded readings included
    leg_pose_jacobian: NDArray[np.float64]  # (N, 6, 6), whitened, excluded readings included
    leg_parameter_jacobian: NDArray[np.float64]  # (N, 6, p), whitened, excluded readings included
    leg_residuals: NDArray[np.float64]  # (N, 6), whitened, excluded readings zero
    pose_normal: NDArray[np.float64]  # U (N, 6, 6)
    coupling: NDArray[np.float64]  # W (N, 6, p)
    parameter_normal: NDArray[np.float64]  # V (p, p)
    pose_gradient: NDArray[np.float64]  # (N, 6)
    parameter_gradient: NDArray[np.float64]  # (p,)
    prior_residuals: NDArray[np.float64]  # (3K,) whitened feature-point priors, or (0,)

    @property
    def cost(self) -> float:
        return float(np.sum(self.point_residuals**2) + np.sum(self.leg_residuals**2) + np.sum(self.prior_residuals**2))


@dataclass(frozen=True, slots=True, eq=False)
class _Fit:
    theta: NDArray[np.float64]
    rotations: NDArray[np.float64]
    translations: NDArray[np.float64]
    linear: _Linearisation
    iterations: int
    converged: bool


def identify_full(data: MeasurementData, nominal: Geometry, options: IdentificationOptions, *,
                  left_out: Collection[ObservationKey] | None = None) -> IdentificationResult:
    """Maximum-likelihood identification from all postures (see the module docstring).

    Starts from ``nominal`` and the poses fitted to each posture's points. Returns status
    INSUFFICIENT_DATA with fewer than :data:`MIN_POSTURES` postures. ``left_out``: the
    observations to leave out (:func:`observation_key` of an excluded one), and no others,
    instead of the search for gross errors: to compare two models on the same observations.
    """
    start = StructuralParameters.from_geometry(nominal, options.estimate_scales)
    reason = "full: all structural parameters at once from every posture's measured pose and all six readings (maximum likelihood)"
    if len(data) < MIN_POSTURES:
        return failed_result(Method.FULL, reason, IdentificationStatus.INSUFFICIENT_DATA, start, data.lines, data.locked_leg,
                             f"full needs at least {MIN_POSTURES} postures, the data have {len(data)}")
    feature_points = np.array(nominal.measurement.feature_points)
    poses = measured_poses(data, feature_points)
    if data.points_mm is None:
        model = feature_points
        observed = np.einsum("nij,kj->nki", poses.rotations, model) + poses.translations[:, None, :]
    else:
        model = feature_points[: data.point_count]
        observed = np.array(data.points_mm)
    sigma = nominal.measurement.point_sigma_mm if options.point_sigma_mm is None else options.point_sigma_mm
    pose_form = data.points_mm is None
    # The campaign's time: the rows' order (a file lists its postures as they were measured).
    times = np.linspace(0.0, 1.0, len(data)) if options.estimate_drift else None
    # Feature points are parameters only where they were observed: a pose-form row's points
    # are implied by its pose through the nominal ones.
    target_sigma = 0.0 if pose_form else nominal.measurement.feature_point_sigma_mm
    covariance = data.point_covariance_mm2
    whitening = None if covariance is None else np.linalg.inv(np.linalg.cholesky(covariance))
    problem = _Problem(observed, model, np.array(data.readings_mm), sigma, options.reading_sigma_mm,
                       options.estimate_scales, np.ones(observed.shape[:2]), np.ones((len(data), LEG_COUNT)), times,
                       target_sigma, whitening)
    theta = np.concatenate((start.to_vector(), np.zeros(LEG_COUNT if times is not None else 0),
                            model.ravel() if target_sigma > 0.0 else np.zeros(0)))
    if left_out is not None:
        problem = problem.with_observation_weights(_weights_without(problem, pose_form, left_out), pose_form)
    initial = theta, np.array(poses.rotations), np.array(poses.translations)
    fit = _fit(problem, *initial, options.max_iterations)
    exclusion_notes: tuple[str, ...] = ()
    if left_out is None:
        fit, problem, exclusion_notes = _exclude_gross_errors(problem, fit, initial, pose_form, options)
    current, theta = fit.linear, fit.theta

    full_information = _reduced_normal(current, 0.0)[0]
    information = _marginal(full_information, problem.structural_size)
    used_points = problem.point_weights.sum(axis=1)
    used_readings = problem.reading_weights.sum(axis=1)
    posture_chi2 = np.sum(current.point_residuals**2, axis=(1, 2)) + np.sum(current.leg_residuals**2, axis=1)
    # Per posture: 3 residuals per used point and 1 per used reading against 6 pose unknowns
    # (the parameters' share of the degrees of freedom is spread thin over the postures and
    # neglected here). A pose-form row's points are those of a rigid pose: only 6 of its 3K
    # residuals are free (the others are zero whatever the noise). A posture whose points are
    # all excluded is pinned by its readings alone: no test.
    observed_dof = np.where(used_points > 0, 6.0, 0.0) if pose_form else 3 * used_points
    posture_dof = np.maximum(observed_dof + used_readings - 6.0, 0.0)
    posture_chi2 = np.where(posture_dof > 0, posture_chi2, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        normalised = posture_chi2 / posture_dof
        fit_rms = np.sqrt(np.sum(current.point_residuals**2, axis=(1, 2)) / (3 * used_points)) * sigma
    residuals = PostureResiduals(
        lines=np.array(data.lines),
        locked_leg=np.array(data.locked_leg),
        fit_rms_mm=fit_rms,
        normalised=normalised,
        outlier=flag_outliers(posture_chi2, np.maximum(posture_dof, 1), options.outlier_probability),
    )
    point_residual_count = 3 * int(used_points.sum())
    dof = (int(observed_dof.sum() + used_readings.sum()) + current.prior_residuals.size - 6 * len(data)
           - len(theta))
    # The leg closures are near-exact constraints (σ_reading ≪ the pose noise they carry), so
    # the point residuals hold practically all the degrees of freedom.
    point_dof_share = min(dof / point_residual_count, 1.0)
    structural, drift, targets = problem.split(theta)
    parameters = StructuralParameters.from_vector(structural, options.estimate_scales)
    warnings = exclusion_notes
    # An unconverged fit's residuals say nothing of the targets (identify() says what to check).
    chi2_per_dof = current.cost / dof if dof > 0 else float("nan")
    if fit.converged and not pose_form and targets is None and (
            misplaced := _misplaced_targets(problem, fit, chi2_per_dof)):
        warnings += (misplaced,)
    result = assemble_result(
        Method.FULL, reason, parameters, information, residuals, current.cost, dof,
        residual_rms_mm=float(np.sqrt(np.sum(problem.in_mm(current.point_residuals) ** 2) / point_residual_count)),
        expected_rms_mm=float(np.sqrt(point_dof_share)) * (
            sigma if covariance is None else float(np.sqrt(np.mean(np.trace(covariance, axis1=2, axis2=3)) / 3.0))),
        iterations=fit.iterations, converged=fit.converged, options=options, home_mm_deg=nominal.home,
        warnings=warnings, excluded=_excluded_observations(problem, fit.linear, pose_form, data),
        covariance=_noise_scaled_covariance(problem, fit, pose_form, full_information, chi2_per_dof),
    )
    extras_std = _extras_std(full_information, problem.structural_size)
    return replace(
        result,
        offset_drift_mm=None if drift is None else Estimate(drift, extras_std[:LEG_COUNT]),
        feature_points_mm=None if targets is None else Estimate(targets, extras_std[-targets.size:].reshape(-1, 3)),
    )


def _noise_scaled_covariance(problem: _Problem, fit: _Fit, pose_form: bool, information: NDArray,
                             chi2_per_dof: float) -> NDArray[np.float64]:
    """The structural parameters' covariance with each observation group's excess noise in
    it: of S⁻¹·(F_p·S_p + F_r·S_r + S_t)·S⁻¹, S = S_p + S_r + S_t the reduced normal matrix
    (``information``) split into the feature points', the readings' and the feature points'
    prior's shares, F_p and F_r the points' and the readings' χ² over their degrees of
    freedom (at least 1; a group with none tested, as the feature points when they are
    parameters, takes ``chi2_per_dof``). One factor for all, χ²/dof, was wrong by orders of
    magnitude when one group's noise figure was: a point noise given as 1e-6 mm against the
    data's 0.25 mm put every σ in metres, the readings' share included."""
    linear = fit.linear
    statistics, dof = _standardised_residuals(problem, linear, pose_form)
    used = problem.observation_weights(pose_form) > 0.0
    factors = []
    for group in (slice(None, -LEG_COUNT), slice(-LEG_COUNT, None)):
        tested = int(np.sum(np.where(used[:, group], dof[:, group], 0)))
        excess = float(np.sum(np.where(used[:, group], statistics[:, group], 0.0))) / tested if tested else chi2_per_dof
        factors.append(excess if excess > 1.0 else 1.0)  # NaN (no degrees of freedom): 1
    pose_inverse = _reduced_normal(linear, 0.0)[2]
    spread = pose_inverse @ linear.coupling  # U⁻¹·W: how each posture's pose follows the parameters
    # Each observation's sensitivity to the parameters once its pose follows them, c = b − a·U⁻¹·W.
    point_jacobian = linear.point_jacobian * problem.point_weights[:, :, None, None]
    points = -np.einsum("nkri,nip->nkrp", point_jacobian, spread)
    _, _, targets = problem.split(fit.theta)
    if targets is not None:
        first = len(fit.theta) - targets.size
        target_jacobians = problem.whiten(np.repeat(fit.rotations[:, None], len(targets), axis=1)) \
            * problem.point_weights[:, :, None, None]
        for k in range(len(targets)):
            points[:, k, :, first + 3 * k : first + 3 * k + 3] += target_jacobians[:, k]
    readings = (linear.leg_parameter_jacobian - np.einsum("nli,nip->nlp", linear.leg_pose_jacobian, spread)) \
        * problem.reading_weights[:, :, None]
    point_share = np.einsum("nkrp,nkrq->pq", points, points)
    reading_share = np.einsum("nlp,nlq->pq", readings, readings)
    inverse = analyse_information(information)[0]  # S⁻¹ on what the data determine
    covariance = inverse @ (information + (factors[0] - 1.0) * point_share
                            + (factors[1] - 1.0) * reading_share) @ inverse
    size = problem.structural_size
    return 0.5 * (covariance[:size, :size] + covariance[:size, :size].T)  # symmetric to the last bit, as files check


TARGET_TEST_FALSE_ALARM = 1e-3
"""The feature-point test's probability of firing on correct data."""


def _misplaced_targets(problem: _Problem, fit: _Fit, chi2_per_dof: float) -> str | None:
    """A warning when the feature points' residuals, seen from the platform, are the same
    posture after posture: the targets are not where ``[measurement]`` says. Each
    posture's pose absorbs a rigid motion of them, so of the 3K mean residuals 3K − 6 are
    free; their χ² (residuals σ-whitened) is tested at :data:`TARGET_TEST_FALSE_ALARM`,
    divided by the fit's ``chi2_per_dof`` where that exceeds 1: residuals larger than the
    noise model all round (an optimistic noise figure) make their means larger too, and
    would otherwise send the user to survey targets that are where they should be."""
    from scipy.stats import chi2  # imported here: slow to import (see results.flag_outliers)

    count = len(problem.model_points)
    dof = 3 * count - 6
    used = problem.point_weights > 0.0
    # Seen from the platform the residuals must be whitened alike: an instrument's
    # anisotropic noise is not (its form is tested by χ² alone).
    if dof <= 0 or np.any(used.sum(axis=0) < 2) or problem.whitening is not None:
        return None
    in_platform = np.einsum("nji,nkj->nki", fit.rotations, fit.linear.point_residuals)  # Tᵀ·r, whitened
    sums = in_platform.sum(axis=0)  # excluded points' residuals are zero
    statistic = float(np.sum(sums**2 / used.sum(axis=0)[:, None])) / max(1.0, chi2_per_dof)  # NaN: unscaled
    threshold = float(chi2.isf(TARGET_TEST_FALSE_ALARM, dof))
    if statistic <= threshold:
        return None
    offsets = np.linalg.norm(sums / used.sum(axis=0)[:, None], axis=1) * problem.point_sigma
    return (f"the feature points' residuals are the same in every posture (χ² {statistic:.0f} with {dof} dof, beyond "
            f"{threshold:.0f}): the targets are not where [measurement] feature_points says, by about "
            f"{', '.join(f'p{k} {offset:.2f} mm' for k, offset in enumerate(offsets, start=1))} (the part a frame "
            "shift cannot hide); measure their coordinates on the platform, or give their tolerance as "
            "feature_point_sigma_mm so the calibration identifies them and predicts honestly")


def _marginal(information: NDArray, size: int) -> NDArray[np.float64]:
    """The information on the first ``size`` parameters with the rest (drift, feature
    points) unknown: the Schur complement of their block."""
    if len(information) == size:
        return information
    kept, other = information[:size, :size], information[:size, size:]
    return kept - other @ np.linalg.pinv(information[size:, size:]) @ other.T


def _extras_std(information: NDArray, size: int) -> NDArray[np.float64]:
    """Standard deviations of the parameters after the first ``size`` (drift, feature points)."""
    if len(information) == size:
        return np.zeros(0)
    return np.sqrt(np.clip(np.diag(np.linalg.pinv(information))[size:], 0.0, None))


def _fit(problem: _Problem, theta: NDArray, rotations: NDArray, translations: NDArray, max_iterations: int) -> _Fit:
    """Levenberg–Marquardt from (θ, poses) to the weighted least-squares minimum."""
    current = _linearise(problem, theta, rotations, translations)
    damping, converged, iteration = 1e-6, False, 0
    for iteration in range(1, max_iterations + 1):
        step_theta, step_poses = _solve(current, damping)
        trial_rotations = Rotation.from_rotvec(step_poses[:, 3:]).as_matrix() @ rotations
        trial = _linearise(problem, theta + step_theta, trial_rotations, translations + step_poses[:, :3])
        change = current.cost - trial.cost
        if change >= 0.0:
            theta, rotations, translations = theta + step_theta, trial_rotations, translations + step_poses[:, :3]
            current = trial
            damping = max(damping / 10.0, 1e-12)
        else:
            damping *= 10.0
        small_step = max(np.max(np.abs(step_theta)), np.max(np.abs(step_poses[:, :3]))) < _STEP_TOLERANCE_MM
        # Near the minimum the cost changes by rounding noise of either sign: both mean done,
        # as does a cost at rounding level (noise-free data, residuals ~1e-10 σ).
        if abs(change) <= _COST_TOLERANCE * current.cost or (change >= 0.0 and small_step) or current.cost < 1e-20:
            converged = True
            break
        if damping > 1e12:  # no downhill step though the gradient is not negligible
            break
    return _Fit(theta, rotations, translations, current, iteration, converged)


ObservationKey = tuple[int, int, int]
"""An observation by its row in the data, feature point and leg, as in :class:`ExcludedObservation`."""


def observation_key(observation: ExcludedObservation) -> ObservationKey:
    return observation.row, observation.point, observation.leg


def _weights_without(problem: _Problem, pose_form: bool, left_out: Collection[ObservationKey]) -> NDArray[np.float64]:
    """:meth:`_Problem.observation_weights` with the ``left_out`` observations at 0, except in
    a posture whose pose they would leave unpinned (two searches may each exclude another
    explanation of one posture's misfit, its points or its readings): it keeps them all."""
    weights = problem.observation_weights(pose_form).copy()
    first_reading = weights.shape[1] - LEG_COUNT
    for row, point, leg in left_out:
        weights[row, first_reading + leg - 1 if leg else max(point - 1, 0)] = 0.0
    unpinned = np.sum(weights * problem.observation_dof(pose_form), axis=1) < 6.0
    weights[unpinned] = problem.observation_weights(pose_form)[unpinned]
    return weights


def _exclude_gross_errors(problem: _Problem, fit: _Fit, initial: tuple[NDArray, NDArray, NDArray], pose_form: bool,
                          options: IdentificationOptions) -> tuple[_Fit, _Problem, tuple[str, ...]]:
    """Exclude gross mis-sightings and reading errors and refit, round by round (see the
    module docstring), from the plain ``fit``, or where it failed from the ``initial`` state
    (θ, rotations, translations).

    Returns the final fit, the problem with its observation weights, and notes for people.
    """
    if options.exclusion_false_alarm <= 0.0:
        return fit, problem, ()
    observations = problem.observation_weights(pose_form).size
    false_alarm = options.exclusion_false_alarm / observations  # Bonferroni: points, poses and readings alike
    usable = fit.converged and _determined(fit.linear)
    if not usable or _beyond(problem, fit, pose_form, np.log(false_alarm)):
        unfitted = _Fit(*initial, _linearise(problem, *initial), 0, False)
        starts = (fit, unfitted) if usable else (unfitted,)
        fit, problem = _robust_start(problem, starts, pose_form, false_alarm, options.max_iterations) \
            or (fit, problem)
    if not fit.converged or not _determined(fit.linear):
        return fit, problem, ()
    cuts = _cuts(false_alarm, pose_form)
    fit, problem, notes = _exclusion_rounds(problem, fit, pose_form, false_alarm, cuts, options.max_iterations)
    excluded = problem.observation_weights(pose_form) == 0.0
    sightings = int(np.count_nonzero(excluded[:, :-LEG_COUNT]))
    readings = int(np.count_nonzero(excluded[:, -LEG_COUNT:]))
    if sightings or readings:
        sighted = "row(s)' measured pose" if pose_form else "feature point(s)"
        what = ([f"{sightings} {sighted} excluded as gross mis-sightings"] if sightings else []) + (
            [f"{readings} reading(s) excluded as gross reading errors"] if readings else [])
        remedy = ("check each listed reading against the posture's record (a typo, a wrong column, a value written "
                  "twice?) and correct it on its line, or measure those postures again" if readings
                  else "measure those postures again if in doubt")
        notes = (f"{' and '.join(what)}: standardised residual beyond the cut ({cuts}) that all {observations} "
                 f"observations of a campaign without gross errors pass with probability "
                 f"{1.0 - options.exclusion_false_alarm:g}; each is listed: {remedy}", *notes)
    return fit, problem, notes


def _beyond(problem: _Problem, fit: _Fit, pose_form: bool, log_cut: float) -> bool:
    """Whether any used observation's standardised residual is beyond the cut."""
    statistics, dof = _standardised_residuals(problem, fit.linear, pose_form)
    used = problem.observation_weights(pose_form) > 0.0
    return bool(np.any(used & (_log_tail_probabilities(statistics, dof) < log_cut)))


_CAUCHY_SCALE = 2.385
"""The Cauchy loss's scale in σ (95 % efficiency on Gaussian noise): an observation's weight
in the robust start is 1 / (1 + χ² / (scale² · dof))."""
_ROBUST_ROUNDS = 30
_ROBUST_WEIGHT_CHANGE = 1e-3  # the robust start's reweighting ends when no weight moves by more


def _robust_start(problem: _Problem, starts: tuple[_Fit, ...], pose_form: bool, false_alarm: float,
                  max_iterations: int) -> tuple[_Fit, _Problem] | None:
    """The fit with the observations a robust fit finds beyond the cut excluded, as the start
    of the exclusion rounds; None where there is nothing to exclude, too much, or the fit
    without them fails.

    Least squares lets gross errors bias the fit they are tested against: 8 % of postures
    mis-sighted by a few mm push most good observations beyond the cut, and one point off by
    metres keeps the fit from converging at all. A Cauchy loss bounds each observation's pull,
    so the gross errors stand out and the good observations fit. But it has local minima: a
    posture's pose can follow its points or its readings, and stays with whichever it starts
    at. So it runs from each of ``starts`` (the plain fit, whose poses follow a wrong reading;
    the measured poses and nominal geometry, which follow a mis-sighted point) and keeps the
    one that calls fewer observations wrong (:func:`_trimmed_cost`). Its weights are not the noise
    model's, so it only chooses where the exclusion rounds begin: they readmit what the plain
    fit without these observations predicts within the cut, and test the rest as before.
    """
    fit = min((_robust_fit(problem, start, pose_form, max_iterations) for start in starts),
              key=lambda candidate: _trimmed_cost(problem, candidate, pose_form, false_alarm))
    used = problem.observation_weights(pose_form) > 0.0
    beyond = used & (_misfit_chi2(problem, fit.linear, pose_form) > _cut_chi2(problem, pose_form, false_alarm))
    beyond = _points_or_reading(problem, fit, beyond, pose_form, false_alarm)
    # Each posture's pose stays pinned: where too few would be left for that, they all stay in.
    kept = np.sum(np.where(used & ~beyond, problem.observation_dof(pose_form), 0.0), axis=1) >= 6.0
    beyond &= kept[:, None]
    touched = np.count_nonzero(np.any(beyond, axis=1))
    if touched == 0 or touched > MAX_EXCLUDED_FRACTION * len(used):
        return None
    start_problem = problem.with_observation_weights(np.where(beyond, 0.0, problem.observation_weights(pose_form)),
                                                     pose_form)
    start = _fit(start_problem, fit.theta, fit.rotations, fit.translations, max_iterations)
    if not start.converged or not _determined(start.linear):
        return None
    return start, start_problem


def _points_or_reading(problem: _Problem, fit: _Fit, beyond: NDArray, pose_form: bool,
                       false_alarm: float) -> NDArray[np.bool_]:
    """``beyond`` (N, M), with each posture's wrong points (pose form: wrong pose) told from a
    wrong reading.

    A posture's pose follows either its feature points (pose form: its measured pose) or its
    six readings, and the robust fit keeps whichever it started at, so "its points beyond the
    cut" is what a wrong reading looks like too: a locked leg's reading off by 7 mm once had
    all three points of its posture excluded, the readings alone pinning the pose, untested.
    As in the exclusion rounds, a reading is tried first: where the observations beyond would
    leave their posture's others no redundancy, the reading whose exclusion leaves the others
    fitting best (at the pose that fits them best, the parameters held) goes instead, if they
    then pass the test (χ² within the cut at their degrees of freedom). Where all six readings
    of a pose-form row are beyond, one wrong pose is likelier than six wrong readings.
    """
    from scipy.stats import chi2  # imported here: slow to import (see results.flag_outliers)

    weights = problem.observation_weights(pose_form)
    dof = problem.observation_dof(pose_form)
    first_reading = beyond.shape[1] - LEG_COUNT
    resolved = beyond.copy()
    unredundant = np.sum(np.where((weights > 0.0) & ~beyond, dof, 0.0), axis=1) <= 6.0
    for row in np.flatnonzero(unredundant & np.any(beyond, axis=1) & ~np.all(beyond[:, first_reading:], axis=1)):
        misfits = []
        for leg in range(LEG_COUNT):
            without = weights[row].copy()
            without[first_reading + leg] = 0.0
            misfits.append(_posture_chi2(problem, fit, row, without, pose_form))
        if min(misfits) <= chi2.isf(false_alarm, np.sum(weights[row] * dof) - 1.0 - 6.0):  # less the pose's 6
            resolved[row] = np.arange(beyond.shape[1]) == first_reading + int(np.argmin(misfits))
    if pose_form:
        wrong_pose = np.all(beyond[:, first_reading:], axis=1)
        resolved[wrong_pose] = np.arange(beyond.shape[1]) == 0
    return resolved


_POSTURE_ITERATIONS = 10  # Gauss–Newton steps of one posture's pose alone: it starts within tens of mm


def _posture_chi2(problem: _Problem, fit: _Fit, row: int, weights: NDArray, pose_form: bool) -> float:
    """The least χ² of one posture's observations weighted ``weights`` (M,), over its pose from
    ``fit``'s, the parameters held at ``fit``'s."""
    rows = slice(row, row + 1)
    posture = replace(problem, observed=problem.observed[rows], readings=problem.readings[rows],
                      point_weights=problem.point_weights[rows], reading_weights=problem.reading_weights[rows],
                      times=None if problem.times is None else problem.times[rows],
                      whitening=None if problem.whitening is None else problem.whitening[rows])
    posture = posture.with_observation_weights(weights[None], pose_form)
    rotations, translations = fit.rotations[rows], fit.translations[rows]
    for _ in range(_POSTURE_ITERATIONS):
        linear = _linearise(posture, fit.theta, rotations, translations)
        step = -np.linalg.solve(linear.pose_normal[0], linear.pose_gradient[0])
        rotations = Rotation.from_rotvec(step[3:]).as_matrix()[None] @ rotations
        translations = translations + step[:3]
    linear = _linearise(posture, fit.theta, rotations, translations)
    return float(np.sum(linear.point_residuals**2) + np.sum(linear.leg_residuals**2))


def _robust_fit(problem: _Problem, fit: _Fit, pose_form: bool, max_iterations: int) -> _Fit:
    """The Cauchy loss's minimum near ``fit``, by iteratively reweighted least squares."""
    weights = np.ones_like(problem.observation_weights(pose_form))
    scales = _CAUCHY_SCALE**2 * problem.observation_dof(pose_form)
    for _ in range(_ROBUST_ROUNDS):
        new_weights = 1.0 / (1.0 + _misfit_chi2(problem, fit.linear, pose_form) / scales)
        settled = np.max(np.abs(new_weights - weights)) < _ROBUST_WEIGHT_CHANGE
        weights = new_weights
        if settled:
            break
        # The problem's weights multiply the whitened residuals: their squares weigh the cost.
        fit = _fit(problem.with_observation_weights(np.sqrt(weights), pose_form), fit.theta, fit.rotations,
                   fit.translations, max_iterations)
    return fit


def _trimmed_cost(problem: _Problem, fit: _Fit, pose_form: bool, false_alarm: float) -> float:
    """Σ over the used observations of χ², but at most the cut's: what the fit of those within
    the cut costs, and a fixed price for each beyond it, higher for an observation of more
    dof (a wrong reading is cheaper than three wrong points, a wrong pose than six readings).
    Unlike the Cauchy loss, it does not grow with how far a gross error is, in units of a
    noise that differs 25-fold between readings and points."""
    cost = np.minimum(_misfit_chi2(problem, fit.linear, pose_form), _cut_chi2(problem, pose_form, false_alarm))
    return float(np.sum(np.where(problem.observation_weights(pose_form) > 0.0, cost, 0.0)))


def _cut_chi2(problem: _Problem, pose_form: bool, false_alarm: float) -> NDArray[np.float64]:
    """(M,): the χ² beyond which each kind of observation is a gross error at ``false_alarm``."""
    from scipy.stats import chi2  # imported here: slow to import (see results.flag_outliers)

    return chi2.isf(false_alarm, problem.observation_dof(pose_form))


def _misfit_chi2(problem: _Problem, linear: _Linearisation, pose_form: bool) -> NDArray[np.float64]:
    """(N, M) each observation's whitened misfit squared, in the order of
    :meth:`_Problem.observation_weights`, whether used or not (no leverage taken out)."""
    points = np.sum(linear.point_misfits**2, axis=2)
    observed = np.sum(points, axis=1, keepdims=True) if pose_form else points
    return np.concatenate((observed, linear.leg_misfits**2), axis=1)


def _cuts(false_alarm: float, pose_form: bool) -> str:
    """The cut on each kind of observation's standardised residual at probability
    ``false_alarm``, in σ, for people."""
    from scipy.stats import chi2  # imported here: slow to import (see results.flag_outliers)

    observed = "a row's pose" if pose_form else "a feature point"
    return (f"{np.sqrt(chi2.isf(false_alarm, 6 if pose_form else 3)):.1f} σ for {observed}, "
            f"{np.sqrt(chi2.isf(false_alarm, 1)):.1f} σ for a reading")


def _exclusion_rounds(problem: _Problem, fit: _Fit, pose_form: bool, false_alarm: float, cuts: str,
                      max_iterations: int) -> tuple[_Fit, _Problem, tuple[str, ...]]:
    count = len(problem.observed)
    log_cut = np.log(false_alarm)
    # Before single-observation rounds (below): the fit to fall back on, and how many postures were touched.
    fallback: tuple[_Fit, _Problem, int] | None = None
    for _ in range(_MAX_EXCLUSION_ROUNDS):
        statistics, dof = _standardised_residuals(problem, fit.linear, pose_form)
        log_tails = _log_tail_probabilities(statistics, dof)
        weights = problem.observation_weights(pose_form)
        rows, worst, dropping = _worst_observations(problem, pose_form, log_tails, log_cut)
        # Bad observations bias the first fits and can push good ones beyond the cut: an
        # excluded observation that the current fit predicts within the cut comes back.
        readmitted = (weights == 0.0) & (log_tails >= log_cut)
        if len(rows) == 0 and not np.any(readmitted):
            return fit, problem, ()
        weights = np.where(readmitted, 1.0, weights)
        touched = int(np.count_nonzero(np.any(weights == 0.0, axis=1) | np.isin(np.arange(count), rows)))
        if touched <= MAX_EXCLUDED_FRACTION * count:
            fallback = None
        else:
            # Too many postures for isolated gross errors: a model error, its misfit spread over
            # the fit, or a few gross errors biasing the whole fit (a wrong reading moves its
            # posture's pose by tens of mm, and the parameters with it), their misfit concentrated.
            # Only the worst observation of all is excluded, while it is concentrated misfit.
            fallback = fallback or (fit, problem, touched)
            rows = rows[[np.argmin(log_tails[rows, worst[rows]])]]
            if statistics[rows[0], worst[rows[0]]] < CONCENTRATED_MISFIT_SHARE * fit.linear.cost:
                return fallback[0], fallback[1], (_too_many(fallback[2], count, cuts),)
        weights[rows[dropping[rows]], -LEG_COUNT:] = 1.0  # see _worst_observations
        weights[rows, worst[rows]] = 0.0
        trial_problem = problem.with_observation_weights(weights, pose_form)
        trial = _fit(trial_problem, fit.theta, fit.rotations, fit.translations, max_iterations)
        if not trial.converged or not _determined(trial.linear):
            if fallback is not None:  # never end with more than the fraction touched
                fit, problem = fallback[0], fallback[1]
            return fit, problem, (
                f"{len(rows)} more observation(s) lie beyond the gross-error cut ({cuts}), but without them some "
                "parameter combination would be undetermined: they are kept; measure those postures again",)
        fit, problem = trial, trial_problem
    if fallback is not None:
        return fallback[0], fallback[1], (_too_many(fallback[2], count, cuts),)
    return fit, problem, (f"gross errors still found after {_MAX_EXCLUSION_ROUNDS} rounds of exclusion: the data "
                          "may hold more bad observations than listed; measure the listed postures again",)


def _worst_observations(problem: _Problem, pose_form: bool, log_tails: NDArray,
                        log_cut: float) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """The observation each posture would exclude this round, from each observation's log
    tail probability (N, M): the postures with one beyond ``log_cut``, its column (N,), and
    whether the posture's excluded readings come back with it (N,).

    The worst is the least probable under the noise model, which weighs a reading (1 dof)
    against a point (3) or a pose (6). But an observation whose exclusion would leave its
    posture no redundancy (a pose-form row's pose: as if the row were dropped) absorbs any
    misfit of its posture, a wrong reading's too, and a wrong reading drags the pose the test
    is linearised at by tens of mm, so that test cannot tell which is wrong. The posture's
    least probable other observation beyond the cut is tried first; if the refit still finds
    the first beyond the cut, it goes, and the readings tried come back (it and they cannot
    all go: they pin the posture's pose).
    """
    used = problem.observation_weights(pose_form) > 0.0
    dof = problem.observation_dof(pose_form)
    wide = (np.sum(used * dof, axis=1) - 6.0)[:, None] - dof <= 0.0  # no redundancy left without it
    candidates = np.where(used & (log_tails < log_cut), log_tails, np.inf)
    narrow, broad = np.where(wide, np.inf, candidates), np.where(wide, candidates, np.inf)
    postures = np.arange(len(used))
    worst = np.argmin(candidates, axis=1)
    tried = np.any(~used, axis=1)
    dropping = tried & np.isfinite(np.min(broad, axis=1))
    narrow_first = ~tried & wide[postures, worst] & np.isfinite(np.min(narrow, axis=1))
    worst = np.where(dropping, np.argmin(broad, axis=1), np.where(narrow_first, np.argmin(narrow, axis=1), worst))
    return np.flatnonzero(np.isfinite(candidates[postures, worst])), worst, dropping


def _too_many(touched: int, count: int, cuts: str) -> str:
    return (f"{touched} of {count} postures have observations beyond the gross-error cut ({cuts}): too many for "
            "isolated mis-sightings or wrong readings, so no more are excluded; the model does not fit these data "
            "(noise figures too small for the instrument, [measurement] point_sigma_mm or --point-sigma? drifting "
            "sensor offsets, joint play, wrong feature-point coordinates or units?)")


def _determined(linear: _Linearisation) -> bool:
    return analyse_information(_reduced_normal(linear, 0.0)[0])[1].full_rank


def _log_tail_probabilities(statistics: NDArray, dof: NDArray) -> NDArray[np.float64]:
    """log P(χ²(dof) > statistic) of each statistic, 0 where dof is 0 (no test), finite
    however far out: where scipy's tail underflows, the leading term of the upper incomplete
    gamma function's asymptotic series (relative error O(dof/statistic), negligible there)."""
    from scipy.special import gammaln  # imported here: slow to import (see results.flag_outliers)
    from scipy.stats import chi2

    log_tails = np.zeros(statistics.shape)
    tested = dof > 0
    with np.errstate(divide="ignore"):
        log_tails[tested] = chi2.logsf(statistics[tested], dof[tested])
    far = ~np.isfinite(log_tails)
    half, shape = statistics[far] / 2.0, dof[far] / 2.0
    log_tails[far] = (shape - 1.0) * np.log(half) - half - gammaln(shape)
    return log_tails


_UNTESTABLE = 1e-9
"""Where a used observation's whitened residual covariance I − H has an eigenvalue below this,
it alone pins that direction of its posture's pose: nothing else predicts it there."""


def _standardised_residuals(problem: _Problem, linear: _Linearisation,
                            pose_form: bool) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """χ² of each tested observation's standardised residual and its degrees of freedom, (N, M)
    in the order of :meth:`_Problem.observation_weights`: a feature point's 3-D residual (pose
    form: a row's whole pose, 6-D), then each reading's leg closure (1-D). A used observation's
    whitened residual has covariance I − H (H its leverage: the share of it the fit absorbs by
    moving its posture's pose and the parameters); an excluded one's, as a prediction, I + H. A
    used observation is tested only in the directions the others predict (:data:`_UNTESTABLE`):
    a reading of a posture whose points are all excluded has none."""
    reduced, _, pose_inverse = _reduced_normal(linear, 0.0)
    blocks = pose_inverse, pose_inverse @ linear.coupling, np.linalg.pinv(reduced)
    a, r = linear.point_jacobian, linear.point_misfits
    if pose_form:
        # The synthetic points of a row move together: its pose (6 dof) is the observation,
        # whitened by its information Aᵀ·A = C·Cᵀ: misfit C⁻¹·Aᵀ·r, Jacobian Cᵀ.
        factor = np.linalg.cholesky(np.einsum("nkri,nkrj->nij", a, a))
        misfits = np.linalg.solve(factor, np.einsum("nkri,nkr->ni", a, r)[..., None])[:, None, :, 0]
        jacobians = np.swapaxes(factor, 1, 2)[:, None]
    else:
        misfits, jacobians = r, a
    used = problem.observation_weights(pose_form) > 0.0
    observed = _chi2(misfits, _leverage(blocks, jacobians, None), used[:, :-LEG_COUNT])
    leverage = _leverage(blocks, linear.leg_pose_jacobian[:, :, None], linear.leg_parameter_jacobian[:, :, None])
    readings = _chi2(linear.leg_misfits[..., None], leverage, used[:, -LEG_COUNT:])
    return np.concatenate((observed[0], readings[0]), axis=1), np.concatenate((observed[1], readings[1]), axis=1)


def _leverage(blocks: tuple[NDArray, NDArray, NDArray], pose_jacobian: NDArray,
              parameter_jacobian: NDArray | None) -> NDArray[np.float64]:
    """H (N, M, d, d) of observations with whitened Jacobians (N, M, d, 6) on their posture's
    pose and (N, M, d, p) on the parameters (None: none of their own), from ``blocks`` = (U⁻¹,
    U⁻¹W, S⁻¹) of the normal equations: [a b]·(inverse normal matrix)·[a b]ᵀ, which by blocks
    is a·U⁻¹·aᵀ + c·S⁻¹·cᵀ with c = b − a·U⁻¹W, the observation's sensitivity to the
    parameters once its pose follows them."""
    pose_inverse, spread, reduced_inverse = blocks
    through_parameters = -np.einsum("nmdi,nip->nmdp", pose_jacobian, spread)
    if parameter_jacobian is not None:
        through_parameters += parameter_jacobian
    return (np.einsum("nmdi,nij,nmej->nmde", pose_jacobian, pose_inverse, pose_jacobian)
            + np.einsum("nmdp,nmep->nmde", through_parameters @ reduced_inverse, through_parameters))


def _chi2(misfits: NDArray, leverage: NDArray, used: NDArray) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(N, M) χ² of whitened misfits (N, M, d) with covariance I − H where ``used``, I + H where
    not (H: ``leverage``), and its degrees of freedom: d, less a used one's directions that are
    :data:`_UNTESTABLE`."""
    sign = np.where(used, -1.0, 1.0)[..., None, None]
    variances, directions = np.linalg.eigh(np.eye(misfits.shape[-1]) + sign * leverage)
    projected = np.einsum("nmde,nmd->nme", directions, misfits)
    tested = variances > _UNTESTABLE
    chi2 = np.sum(np.where(tested, projected**2 / np.where(tested, variances, 1.0), 0.0), axis=-1)
    return chi2, np.count_nonzero(tested, axis=-1)


def _excluded_observations(problem: _Problem, linear: _Linearisation, pose_form: bool,
                           data: MeasurementData) -> tuple[ExcludedObservation, ...]:
    excluded = problem.observation_weights(pose_form) == 0.0
    if not np.any(excluded):
        return ()
    sigmas = np.sqrt(_standardised_residuals(problem, linear, pose_form)[0])
    distances = np.linalg.norm(problem.in_mm(linear.point_misfits), axis=2)
    reading_errors = np.abs(linear.leg_misfits) * problem.reading_sigma
    first_reading = excluded.shape[1] - LEG_COUNT
    found = []
    for row, column in zip(*np.nonzero(excluded)):
        line, sigma = int(data.lines[row]), float(sigmas[row, column])
        if column >= first_reading:
            leg = column - first_reading
            found.append(ExcludedObservation(line, int(row), 0, float(reading_errors[row, leg]), sigma, int(leg) + 1))
        elif pose_form:  # its distance: the farthest of the feature points its pose implies
            found.append(ExcludedObservation(line, int(row), 0, float(np.max(distances[row])), sigma))
        else:
            found.append(ExcludedObservation(line, int(row), int(column) + 1, float(distances[row, column]), sigma))
    return tuple(found)


def _linearise(problem: _Problem, theta: NDArray, rotations: NDArray, translations: NDArray) -> _Linearisation:
    """Whitened residuals and the blocks of the normal equations at (θ, poses)."""
    structural, drift, targets = problem.split(theta)
    parameters = StructuralParameters.from_vector(structural, problem.with_scales)
    count = len(rotations)

    rotated_points = np.einsum("nij,kj->nki", rotations, problem.model_points if targets is None else targets)
    point_misfits = problem.whiten(rotated_points + translations[:, None, :] - problem.observed)
    all_point_jacobian = problem.whiten(point_twist_jacobians(rotated_points))  # (N, K, 3, 6)
    point_residuals = point_misfits * problem.point_weights[:, :, None]
    point_jacobian = all_point_jacobian * problem.point_weights[:, :, None, None]

    rotated_joints = np.einsum("nij,kj->nki", rotations, parameters.platform_joints_mm)
    vectors = rotated_joints + translations[:, None, :] - parameters.base_joints_mm[None, :, :]
    lengths = np.linalg.norm(vectors, axis=2)
    units = vectors / lengths[:, :, None]
    gains = 1.0 + (parameters.scale_errors if parameters.scale_errors is not None else np.zeros(LEG_COUNT))
    offsets = parameters.zero_lengths_mm + (0.0 if drift is None else np.outer(problem.times - 1.0, drift))
    leg_misfits = (lengths - offsets - gains * problem.readings) / problem.reading_sigma
    leg_pose_jacobian = np.concatenate((units, np.cross(rotated_joints, units)), axis=2) / problem.reading_sigma

    size = len(theta)
    leg_parameter_jacobian = np.zeros((count, LEG_COUNT, size))
    for leg in range(LEG_COUNT):
        columns = PARAMETERS_PER_LEG * leg
        leg_parameter_jacobian[:, leg, columns : columns + 3] = -units[:, leg]
        leg_parameter_jacobian[:, leg, columns + 3 : columns + 6] = np.einsum("nji,nj->ni", rotations, units[:, leg])
        leg_parameter_jacobian[:, leg, columns + 6] = -1.0
        if problem.with_scales:
            leg_parameter_jacobian[:, leg, 6 * PARAMETERS_PER_LEG + leg] = -problem.readings[:, leg] / SCALE_UNIT
        if drift is not None:
            leg_parameter_jacobian[:, leg, problem.structural_size + leg] = 1.0 - problem.times
    leg_parameter_jacobian /= problem.reading_sigma
    # An excluded reading drops out as an excluded point does: weight 0 on residual and Jacobians.
    leg_residuals = leg_misfits * problem.reading_weights
    used_pose_jacobian = leg_pose_jacobian * problem.reading_weights[:, :, None]
    used_parameter_jacobian = leg_parameter_jacobian * problem.reading_weights[:, :, None]

    pose_normal = np.einsum("nkri,nkrj->nij", point_jacobian, point_jacobian) + np.einsum(
        "nli,nlj->nij", used_pose_jacobian, used_pose_jacobian)
    coupling = np.einsum("nli,nlp->nip", used_pose_jacobian, used_parameter_jacobian)
    parameter_normal = np.einsum("nlp,nlq->pq", used_parameter_jacobian, used_parameter_jacobian)
    parameter_gradient = np.einsum("nlp,nl->p", used_parameter_jacobian, leg_residuals)
    prior_residuals = np.zeros(0)
    if targets is not None:
        # ∂(T·q_k + R)/∂q_k = T: each feature point's columns, and its prior (q_k − q_k⁰)/σ_t.
        first = len(theta) - targets.size
        target_jacobians = problem.whiten(np.repeat(rotations[:, None], len(targets), axis=1)) \
            * problem.point_weights[:, :, None, None]  # (N, K, 3, 3)
        for k in range(len(targets)):
            columns = slice(first + 3 * k, first + 3 * k + 3)
            target_jacobian = target_jacobians[:, k]
            coupling[:, :, columns] += np.einsum("nri,nrj->nij", point_jacobian[:, k], target_jacobian)
            parameter_normal[columns, columns] += np.einsum("nri,nrj->ij", target_jacobian, target_jacobian)
            parameter_gradient[columns] += np.einsum("nri,nr->i", target_jacobian, point_residuals[:, k])
        prior_residuals = (targets - problem.model_points).ravel() / problem.target_sigma
        block = slice(first, len(theta))
        parameter_normal[block, block] += np.eye(targets.size) / problem.target_sigma**2
        parameter_gradient[block] += prior_residuals / problem.target_sigma
    return _Linearisation(
        point_misfits=point_misfits,
        point_jacobian=all_point_jacobian,
        point_residuals=point_residuals,
        leg_misfits=leg_misfits,
        leg_pose_jacobian=leg_pose_jacobian,
        leg_parameter_jacobian=leg_parameter_jacobian,
        leg_residuals=leg_residuals,
        pose_normal=pose_normal,
        coupling=coupling,
        parameter_normal=parameter_normal,
        pose_gradient=np.einsum("nkri,nkr->ni", point_jacobian, point_residuals)
        + np.einsum("nli,nl->ni", used_pose_jacobian, leg_residuals),
        parameter_gradient=parameter_gradient,
        prior_residuals=prior_residuals,
    )


def _reduced_normal(linear: _Linearisation, damping: float) -> tuple[NDArray, NDArray, NDArray]:
    """(S, rhs, U⁻¹): the poses eliminated from the damped normal equations."""
    pose_normal = linear.pose_normal + damping * np.einsum("nii->ni", linear.pose_normal)[:, :, None] * np.eye(6)
    parameter_normal = linear.parameter_normal + damping * np.diag(np.diag(linear.parameter_normal))
    pose_inverse = np.linalg.inv(pose_normal)
    weighted = np.transpose(linear.coupling, (0, 2, 1)) @ pose_inverse  # Wᵀ U⁻¹, (N, p, 6)
    reduced = parameter_normal - np.einsum("npi,niq->pq", weighted, linear.coupling)
    rhs = linear.parameter_gradient - np.einsum("npi,ni->p", weighted, linear.pose_gradient)
    return reduced, rhs, pose_inverse


def _solve(linear: _Linearisation, damping: float) -> tuple[NDArray, NDArray]:
    """The damped Gauss–Newton step (δθ, δposes) with δposes (N, 6) twists."""
    reduced, rhs, pose_inverse = _reduced_normal(linear, damping)
    step_theta = -np.linalg.lstsq(reduced, rhs, rcond=None)[0]
    step_poses = -np.einsum("nij,nj->ni", pose_inverse, linear.pose_gradient + linear.coupling @ step_theta)
    return step_theta, step_poses
