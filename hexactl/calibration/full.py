"""``full``: every structural parameter from every posture, by maximum likelihood.

Errors-in-variables model. Unknowns: the 42 structural parameters θ (optionally six sensor
scale errors) and each posture's true pose (6 per posture). Observations and residuals,
each divided by its noise standard deviation:

- feature points: T_j·p_k + R_j − m_jk (σ = point_sigma_mm per coordinate);
- leg closure, all six legs, locked or free: ‖T_j·P_i + R_j − B_i‖ − zero_i − (1 + s_i)·l_ij
  (σ = reading_sigma_mm).

Minimising their sum of squares is the maximum-likelihood estimate for Gaussian noise and
reaches the Cramér–Rao bound. The fixed frame is the instrument's and the moving frame the
feature points', so there is no gauge freedom and all 42 parameters are observable with
varied postures (the singular values in the result check it on the actual data).

Pose-form data (no points) are handled by the same model: the measured pose is turned into
the feature points it implies, which weights it exactly as a point fit would.

Solver: Levenberg–Marquardt on the sparse problem by the Schur complement, as in bundle
adjustment. Each posture's 6×6 pose block is eliminated, leaving a p×p system; the reduced
normal matrix at the solution is the parameters' Fisher information, whose inverse is
their covariance. Pose updates are rotation vectors applied on the left, so the Euler
chart's singularities never enter the iteration. Cost: O(N·p²) per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hexactl.calibration.data import MeasurementData, measured_poses
from hexactl.calibration.jacobians import point_twist_jacobians
from hexactl.calibration.parameters import PARAMETERS_PER_LEG, SCALE_UNIT, StructuralParameters
from hexactl.calibration.results import (
    MIN_POSTURES,
    IdentificationOptions,
    IdentificationResult,
    IdentificationStatus,
    Method,
    PostureResiduals,
    assemble_result,
    failed_result,
    flag_outliers,
)
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LEG_COUNT

_STEP_TOLERANCE_MM = 1e-9  # parameter and pose steps below this end the iteration
_COST_TOLERANCE = 1e-10  # relative cost decrease below this ends the iteration


@dataclass(frozen=True, slots=True, eq=False)
class _Problem:
    """The fixed inputs: observed points (N, K, 3), their model (K, 3), readings (N, 6)."""

    observed: NDArray[np.float64]
    model_points: NDArray[np.float64]
    readings: NDArray[np.float64]
    point_sigma: float
    reading_sigma: float
    with_scales: bool


@dataclass(frozen=True, slots=True, eq=False)
class _Linearisation:
    point_residuals: NDArray[np.float64]  # (N, K, 3), whitened
    leg_residuals: NDArray[np.float64]  # (N, 6), whitened
    pose_normal: NDArray[np.float64]  # U (N, 6, 6)
    coupling: NDArray[np.float64]  # W (N, 6, p)
    parameter_normal: NDArray[np.float64]  # V (p, p)
    pose_gradient: NDArray[np.float64]  # (N, 6)
    parameter_gradient: NDArray[np.float64]  # (p,)

    @property
    def cost(self) -> float:
        return float(np.sum(self.point_residuals**2) + np.sum(self.leg_residuals**2))


def identify_full(data: MeasurementData, nominal: Geometry, options: IdentificationOptions) -> IdentificationResult:
    """Maximum-likelihood identification from all postures (see the module docstring).

    Starts from ``nominal`` and the poses fitted to each posture's points. Returns status
    INSUFFICIENT_DATA with fewer than :data:`MIN_POSTURES` postures.
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
    problem = _Problem(observed, model, np.array(data.readings_mm), sigma, options.reading_sigma_mm, options.estimate_scales)

    theta = start.to_vector()
    rotations, translations = np.array(poses.rotations), np.array(poses.translations)
    current = _linearise(problem, theta, rotations, translations)
    damping, converged, iteration = 1e-6, False, 0
    for iteration in range(1, options.max_iterations + 1):
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

    information = _reduced_normal(current, 0.0)[0]
    point_count = observed.shape[1]
    posture_chi2 = np.sum(current.point_residuals**2, axis=(1, 2)) + np.sum(current.leg_residuals**2, axis=1)
    # Per posture: 3K point + 6 leg residuals against 6 pose unknowns (the parameters' share
    # of the degrees of freedom is spread thin over the postures and neglected here).
    posture_dof = 3 * point_count
    residuals = PostureResiduals(
        lines=np.array(data.lines),
        locked_leg=np.array(data.locked_leg),
        fit_rms_mm=np.sqrt(np.mean(current.point_residuals**2, axis=(1, 2))) * sigma,
        normalised=posture_chi2 / posture_dof,
        outlier=flag_outliers(posture_chi2, posture_dof, options.outlier_probability),
    )
    residual_count = current.point_residuals.size + current.leg_residuals.size
    dof = residual_count - 6 * len(data) - len(theta)
    # The leg closures are near-exact constraints (σ_reading ≪ the pose noise they carry), so
    # the point residuals hold practically all the degrees of freedom.
    point_dof_share = min(dof / current.point_residuals.size, 1.0)
    parameters = StructuralParameters.from_vector(theta, options.estimate_scales)
    warnings = ()
    if options.estimate_scales:
        warnings = ("sensor scale errors are identified but the kinematics does not apply them: "
                    "correct the sensors' scaling in the drives if they are significant",)
    return assemble_result(
        Method.FULL, reason, parameters, information, residuals, current.cost, dof,
        residual_rms_mm=float(np.sqrt(np.mean(current.point_residuals**2))) * sigma,
        expected_rms_mm=sigma * float(np.sqrt(point_dof_share)),
        iterations=iteration, converged=converged, options=options, home_mm_deg=nominal.home, warnings=warnings,
    )


def _linearise(problem: _Problem, theta: NDArray, rotations: NDArray, translations: NDArray) -> _Linearisation:
    """Whitened residuals and the blocks of the normal equations at (θ, poses)."""
    parameters = StructuralParameters.from_vector(theta, problem.with_scales)
    count = len(rotations)

    rotated_points = np.einsum("nij,kj->nki", rotations, problem.model_points)
    point_residuals = (rotated_points + translations[:, None, :] - problem.observed) / problem.point_sigma
    point_jacobian = point_twist_jacobians(rotated_points) / problem.point_sigma  # (N, K, 3, 6)

    rotated_joints = np.einsum("nij,kj->nki", rotations, parameters.platform_joints_mm)
    vectors = rotated_joints + translations[:, None, :] - parameters.base_joints_mm[None, :, :]
    lengths = np.linalg.norm(vectors, axis=2)
    units = vectors / lengths[:, :, None]
    gains = 1.0 + (parameters.scale_errors if parameters.scale_errors is not None else np.zeros(LEG_COUNT))
    leg_residuals = (lengths - parameters.zero_lengths_mm - gains * problem.readings) / problem.reading_sigma
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
    leg_parameter_jacobian /= problem.reading_sigma

    pose_normal = np.einsum("nkri,nkrj->nij", point_jacobian, point_jacobian) + np.einsum(
        "nli,nlj->nij", leg_pose_jacobian, leg_pose_jacobian)
    return _Linearisation(
        point_residuals=point_residuals,
        leg_residuals=leg_residuals,
        pose_normal=pose_normal,
        coupling=np.einsum("nli,nlp->nip", leg_pose_jacobian, leg_parameter_jacobian),
        parameter_normal=np.einsum("nlp,nlq->pq", leg_parameter_jacobian, leg_parameter_jacobian),
        pose_gradient=np.einsum("nkri,nkr->ni", point_jacobian, point_residuals)
        + np.einsum("nli,nl->ni", leg_pose_jacobian, leg_residuals),
        parameter_gradient=np.einsum("nlp,nl->p", leg_parameter_jacobian, leg_residuals),
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
