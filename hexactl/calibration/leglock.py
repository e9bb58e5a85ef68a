"""``leglock``: the paper's leg-lock method done right, one leg at a time.

With leg i locked the platform joint P_i moves on a sphere about B_i: for every posture j
with that leg locked, ‖T^j·P_mi + R^j − B_i‖ = zero_i + l_ij (paper, equations 4–8, with
the common length split into the zero length and the locked sensor reading, so a reading
that wobbles by micrometres is still used exactly). Unknowns per leg: B_i, P_mi, zero_i
(seven); T^j and R^j come from the measured postures.

Residuals are in length units divided by each posture's length uncertainty (the pose-fit
covariance of the feature points propagated onto the leg), solved by scipy's bounded
trust-region least squares with bounds at a configurable deviation from the nominal (the
paper's boundary conditions) and an optional robust loss.

Observability: a single locked leg's seven parameters are determined only through the
platform's rotation. Moving P_mi along the leg, B_i along the leg and the zero length
together changes nothing for postures that share the leg direction; the spread of
directions in the data (and the bounds) break that near-degeneracy, and the result's
singular values and predicted accuracy report how well it was broken. Only the locked
leg's reading is used; the free legs' readings are what ``full`` adds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import block_diag
from scipy.optimize import least_squares

from hexactl.calibration.data import MeasuredPoses, MeasurementData, measured_poses
from hexactl.calibration.jacobians import point_fit_twist_covariance
from hexactl.calibration.parameters import PARAMETERS_PER_LEG, StructuralParameters, leg_columns, parameter_names
from hexactl.calibration.results import (
    MIN_LOCKED_POSTURES,
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
from hexactl.kinematics.inverse import LEG_COUNT, twist_jacobian


@dataclass(frozen=True, slots=True, eq=False)
class LockedLegData:
    """One leg's locked postures: ``rows`` into the data, measured ``rotations`` (m, 3, 3)
    and ``translations`` (m, 3), the locked leg's ``readings`` (m,), mm, and each posture's
    leg-length standard deviation ``sigmas`` (m,), mm."""

    leg: int
    rows: NDArray[np.intp]
    rotations: NDArray[np.float64]
    translations: NDArray[np.float64]
    readings: NDArray[np.float64]
    sigmas: NDArray[np.float64]


def locked_leg_data(data: MeasurementData, poses: MeasuredPoses, nominal: Geometry, leg: int,
                    point_sigma_mm: float, reading_sigma_mm: float) -> LockedLegData:
    """Collect leg ``leg``'s (1–6) locked postures and weight them.

    The weight: var(length) = g·Σ·gᵀ + σ_reading², with Σ the twist covariance of a pose fitted
    to the feature points and g the leg's twist-Jacobian row (at the nominal joints; the
    weights barely depend on millimetres of joint error).
    """
    rows = data.locked_rows(leg)
    feature_points = np.array(nominal.measurement.feature_points)
    if data.points_mm is not None:
        feature_points = feature_points[: data.point_count]
    covariance = point_fit_twist_covariance(poses.rotations[rows], feature_points, point_sigma_mm)
    gradients = np.array([twist_jacobian(nominal.legs, poses.poses[row])[0][leg - 1] for row in rows]).reshape(-1, 6)
    variance = np.einsum("mi,mij,mj->m", gradients, covariance, gradients) + reading_sigma_mm**2
    return LockedLegData(leg, rows, poses.rotations[rows], poses.translations[rows],
                         data.readings_mm[rows, leg - 1], np.sqrt(variance))


def locked_leg_residuals(x: NDArray, leg_data: LockedLegData) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Whitened residuals (m,) and their Jacobian (m, 7) for x = [B_i, P_mi, zero_i]."""
    base, platform, zero = x[0:3], x[3:6], x[6]
    rotated = leg_data.rotations @ platform
    vectors = rotated + leg_data.translations - base
    lengths = np.linalg.norm(vectors, axis=1)
    units = vectors / lengths[:, None]
    residuals = (lengths - zero - leg_data.readings) / leg_data.sigmas
    jacobian = np.hstack((-units, np.einsum("mji,mj->mi", leg_data.rotations, units), -np.ones((len(units), 1))))
    return residuals, jacobian / leg_data.sigmas[:, None]


def too_few_locked(data: MeasurementData) -> str | None:
    """None when every leg has enough locked postures, else a sentence naming legs and lines."""
    problems = []
    for leg in range(1, LEG_COUNT + 1):
        rows = data.locked_rows(leg)
        if len(rows) < MIN_LOCKED_POSTURES:
            where = f" (lines {', '.join(str(int(data.lines[row])) for row in rows)})" if len(rows) else ""
            problems.append(f"leg {leg} has {len(rows)} locked posture(s){where}")
    if not problems:
        return None
    return f"{'; '.join(problems)}: each leg needs at least {MIN_LOCKED_POSTURES} locked postures"


def parameter_bounds(nominal: StructuralParameters, options: IdentificationOptions, leg: int) -> tuple[NDArray, NDArray]:
    """Leg ``leg``'s (1–6) box [B, P, zero] around the nominal: the paper's boundary conditions."""
    centre = nominal.to_vector()[leg_columns(leg - 1)]
    width = np.array([options.max_joint_deviation_mm] * 6 + [options.max_zero_length_deviation_mm])
    return centre - width, centre + width


def leg_by_leg_result(method: Method, reason: str, data: MeasurementData, nominal: Geometry,
                      options: IdentificationOptions, estimates: list[NDArray], legs: list[LockedLegData],
                      iterations: int, converged: bool, warnings: list[str]) -> IdentificationResult:
    """Assemble a result from per-leg estimates x = [B, P, zero] (shared with ``paper``)."""
    information_blocks, chi2_total, dof = [], 0.0, 0
    fit_rms = np.full(len(data), np.nan)
    normalised = np.full(len(data), np.nan)
    squared_lengths, expected = [], []
    for x, leg_data in zip(estimates, legs):
        residuals, jacobian = locked_leg_residuals(x, leg_data)
        # Gauss–Newton information of the plain fit. With a robust loss it ignores the
        # down-weighting, so the standard deviations are slightly optimistic when postures
        # were down-weighted (the outlier list says which).
        information_blocks.append(jacobian.T @ jacobian)
        count = len(residuals)
        share = (count - PARAMETERS_PER_LEG) / count
        chi2_total += float(residuals @ residuals)
        dof += count - PARAMETERS_PER_LEG
        fit_rms[leg_data.rows] = np.abs(residuals * leg_data.sigmas)
        normalised[leg_data.rows] = residuals**2 / share
        squared_lengths.append((residuals * leg_data.sigmas) ** 2)
        expected.append(leg_data.sigmas**2 * share)
    vector = np.concatenate(estimates)
    parameters = StructuralParameters.from_vector(vector, with_scales=False)
    free = int(np.count_nonzero(data.locked_leg == 0))
    if free:
        warnings.append(f"{free} free posture(s) (leg 0) are not used by {method}: 'full' would use them")
    chi2_values = np.where(np.isfinite(normalised), normalised, np.nan)
    residuals = PostureResiduals(np.array(data.lines), np.array(data.locked_leg), fit_rms, normalised,
                                 flag_outliers(chi2_values, 1.0, options.outlier_probability))
    return assemble_result(
        method, reason, parameters, block_diag(*information_blocks), residuals, chi2_total, dof,
        residual_rms_mm=float(np.sqrt(np.mean(np.concatenate(squared_lengths)))),
        expected_rms_mm=float(np.sqrt(np.mean(np.concatenate(expected)))),
        iterations=iterations, converged=converged, options=options, home_mm_deg=nominal.home,
        warnings=tuple(warnings),
    )


def leg_problems(data: MeasurementData, nominal: Geometry, options: IdentificationOptions, method: Method,
                 reason: str) -> list[tuple[LockedLegData, NDArray, NDArray, NDArray]] | IdentificationResult:
    """What each leg's fit starts from, legs 1–6: its locked-posture data, the lower and
    upper parameter bounds and the start (the nominal parameters), in the layout (B, P,
    zero); or, when a leg has fewer than :data:`MIN_LOCKED_POSTURES` locked postures, the
    INSUFFICIENT_DATA result of ``method`` naming legs and lines."""
    start = StructuralParameters.from_geometry(nominal)
    if shortage := too_few_locked(data):
        return failed_result(method, reason, IdentificationStatus.INSUFFICIENT_DATA, start,
                             data.lines, data.locked_leg, shortage)
    sigma = nominal.measurement.point_sigma_mm if options.point_sigma_mm is None else options.point_sigma_mm
    poses = measured_poses(data, np.array(nominal.measurement.feature_points))
    problems = []
    for leg in range(1, LEG_COUNT + 1):
        low, high = parameter_bounds(start, options, leg)
        problems.append((locked_leg_data(data, poses, nominal, leg, sigma, options.reading_sigma_mm), low, high,
                         start.to_vector()[leg_columns(leg - 1)]))
    return problems


def identify_leglock(data: MeasurementData, nominal: Geometry, options: IdentificationOptions) -> IdentificationResult:
    """Each leg's B_i, P_mi and zero length from its locked postures (module docstring).

    Returns INSUFFICIENT_DATA, naming legs and lines, when a leg has fewer than
    :data:`MIN_LOCKED_POSTURES` locked postures. Scale errors are not identifiable from a
    constant reading and are never estimated here.
    """
    reason = ("leglock: each leg's joints and zero length from the postures with that leg locked "
              "(bounded trust-region least squares, residuals whitened by the pose uncertainty)")
    problems = leg_problems(data, nominal, options, Method.LEGLOCK, reason)
    if isinstance(problems, IdentificationResult):
        return problems
    names = parameter_names(with_scales=False)
    estimates, legs, warnings = [], [], []
    iterations, converged = 0, True
    for leg, (leg_data, low, high, x0) in enumerate(problems, start=1):
        solution = least_squares(
            lambda x, d=leg_data: locked_leg_residuals(x, d)[0], x0,
            jac=lambda x, d=leg_data: locked_leg_residuals(x, d)[1],
            bounds=(low, high), method="trf", loss=options.loss, f_scale=1.0,
            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=options.max_iterations * PARAMETERS_PER_LEG,
        )
        iterations = max(iterations, int(solution.nfev))
        converged &= solution.status > 0
        for index in np.flatnonzero(solution.active_mask):
            name = names[leg_columns(leg - 1)][index]
            warnings.append(f"{name} stopped at its bound (nominal ± {high[index] - x0[index]:g} mm): the data do "
                            "not determine it within the allowed deviation")
        estimates.append(solution.x)
        legs.append(leg_data)
    return leg_by_leg_result(Method.LEGLOCK, reason, data, nominal, options, estimates, legs, iterations, converged, warnings)
