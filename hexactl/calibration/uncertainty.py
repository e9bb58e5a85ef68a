"""Fisher information, observability and the Cramér–Rao bound on pose accuracy.

The measurement model behind every figure here: each posture's feature points are
measured with isotropic noise ``point_sigma_mm`` per coordinate, the six sensor readings
with ``reading_sigma_mm``. Marginalising the posture's unknown pose out of the
errors-in-variables model gives the information one posture carries about the 42
structural parameters θ:

    I_j = C_jᵀ (G_j Σ_j G_jᵀ + σ_r² I)⁻¹ C_j

with C_j = ∂(leg closure)/∂θ, G_j = ∂(leg length)/∂(pose twist) and Σ_j the covariance of
the pose fitted to the points. Σ_j I_j⁻¹ is the Cramér–Rao bound, which the ``full``
maximum-likelihood identification reaches (its Schur-complement normal matrix is the same
matrix). Parameter covariance is then propagated to the error of commanded poses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.jacobians import angular_velocity_matrix, length_pose_jacobian, point_fit_twist_covariance
from hexactl.calibration.parameters import GEOMETRIC_PARAMETERS, PARAMETERS_PER_LEG, SCALE_UNIT, parameter_names
from hexactl.calibration.test_motions import TestMotion
from hexactl.kinematics.inverse import LEG_COUNT, LegModel, leg_vectors_batch, sensor_setpoints_batch, twist_jacobian
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_matrices

DEFAULT_READING_SIGMA_MM = 0.01
"""Default sensor-reading noise, 1σ, mm: encoder resolution plus actuator model error."""

RANK_TOLERANCE = 1e-10
"""Singular values below this fraction of the largest count as zero (rank deficiency)."""

UNDETERMINED_STD_MM = 100.0
"""A parameter combination the data know no better than this (1σ) is not determined by
them. Noise alone separates postures that are really one (a posture measured again and
again) by information that pins such combinations to metres; counting them as determined
would hide that the data hold one posture. The plausibility bounds are 60 mm."""

UNDETERMINED_SHARE = 1e-4
"""A parameter with more than this share of its unit vector in the undetermined directions
(a component above 0.01 in one of them) is itself undetermined: such a direction is
known no better than :data:`UNDETERMINED_STD_MM`, so the parameter no better than a
millimetre, whatever the covariance on the determined directions says."""


def closure_parameter_jacobian(legs: LegModel, poses: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(C, units): C (N, 6, 42) = ∂(‖T·P_i + R − B_i‖ − zero_i)/∂θ; units (N, 6, 3) leg directions.

    Row i of posture n is non-zero only in leg i's seven columns: [−u, Tᵀu, −1].
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    vectors = leg_vectors_batch(legs, poses)
    units = vectors / np.linalg.norm(vectors, axis=2, keepdims=True)
    rotations = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    jacobian = np.zeros((len(poses), LEG_COUNT, GEOMETRIC_PARAMETERS))
    for leg in range(LEG_COUNT):
        start = PARAMETERS_PER_LEG * leg
        jacobian[:, leg, start : start + 3] = -units[:, leg]
        jacobian[:, leg, start + 3 : start + 6] = np.einsum("nji,nj->ni", rotations, units[:, leg])
        jacobian[:, leg, start + 6] = -1.0
    return jacobian, units


def posture_information_factors(
    legs: LegModel, poses: NDArray, feature_points_mm: NDArray, point_sigma_mm: float, reading_sigma_mm: float,
    used_readings: NDArray | None = None,
) -> NDArray[np.float64]:
    """Square roots F_j (N, 6, 42) of each posture's information about θ (I_j = F_jᵀF_j).

    ``poses`` (N, 6) absolute (mm, rad), the postures' true (or planned) poses.
    ``used_readings`` (N, 6) bool, default all: the readings an estimator uses (e.g. only
    the locked leg's, for ``leglock``); the others carry no information.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    closure, _ = closure_parameter_jacobian(legs, poses)
    rotations = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    pose_covariance = point_fit_twist_covariance(rotations, feature_points_mm, point_sigma_mm)
    twist = np.array([twist_jacobian(legs, pose)[0] for pose in poses])
    length_covariance = twist @ pose_covariance @ np.transpose(twist, (0, 2, 1))
    length_covariance += reading_sigma_mm**2 * np.eye(LEG_COUNT)
    if used_readings is not None:
        # An unused reading is one with unbounded noise: a variance far beyond every other
        # entry marginalises it out (exactly, to rounding) without changing the shapes.
        length_covariance += np.einsum("nl,lk->nlk", 1e16 * ~np.asarray(used_readings, dtype=bool), np.eye(LEG_COUNT))
    cholesky = np.linalg.cholesky(length_covariance)
    return np.linalg.solve(cholesky, closure)


def fisher_information(
    legs: LegModel, poses: NDArray, feature_points_mm: NDArray, point_sigma_mm: float, reading_sigma_mm: float,
    used_readings: NDArray | None = None,
) -> NDArray[np.float64]:
    """The 42×42 Fisher information of the postures ``poses`` (absolute, mm and rad);
    ``used_readings`` as in :func:`posture_information_factors`."""
    factors = posture_information_factors(legs, poses, feature_points_mm, point_sigma_mm, reading_sigma_mm, used_readings)
    return np.einsum("nri,nrj->ij", factors, factors)


@dataclass(frozen=True, slots=True, eq=False)
class Observability:
    """How well the data determine the parameters (all in mm: every parameter is a length).

    ``singular_values`` of the noise-whitened Jacobian (1/mm), largest first;
    ``worst_std_mm`` = 1/smallest: the standard deviation of the worst-determined parameter
    combination ``worst_direction`` (unit vector); ``rank`` counts the determined ones;
    ``undetermined`` marks each parameter the data do not determine (one in an
    undetermined combination: :data:`UNDETERMINED_SHARE`).
    """

    singular_values: NDArray[np.float64]
    condition_number: float
    worst_std_mm: float
    worst_direction: NDArray[np.float64]
    rank: int
    undetermined: NDArray[np.bool_]

    @property
    def full_rank(self) -> bool:
        return self.rank == len(self.singular_values)

    def worst_direction_terms(self, with_scales: bool, count: int = 4) -> str:
        """The worst direction's largest components, e.g. ``0.71·B3.z − 0.70·zero3``."""
        names = parameter_names(with_scales)
        order = np.argsort(-np.abs(self.worst_direction))[:count]
        return " ".join(f"{'+' if self.worst_direction[k] >= 0 else '−'}{abs(self.worst_direction[k]):.2f}·{names[k]}" for k in order).lstrip("+")


def analyse_information(information: NDArray) -> tuple[NDArray[np.float64], Observability]:
    """(covariance, observability) from an information matrix (p, p).

    The covariance is the inverse on the determined subspace (pseudo-inverse), with the
    undetermined directions (rank deficiency, or 1σ beyond :data:`UNDETERMINED_STD_MM`)
    left out, so it must be read together with ``rank`` and ``undetermined``.
    """
    information = 0.5 * (np.asarray(information, dtype=float) + np.asarray(information, dtype=float).T)
    eigenvalues, vectors = np.linalg.eigh(information)
    eigenvalues = np.clip(eigenvalues, 0.0, None)
    singular = np.sqrt(eigenvalues)[::-1]
    vectors = vectors[:, ::-1]
    largest = singular[0] if singular[0] > 0 else 1.0
    determined = singular > max(RANK_TOLERANCE * largest, 1.0 / UNDETERMINED_STD_MM)
    inverse = np.where(determined, 1.0 / np.where(determined, singular, 1.0) ** 2, 0.0)
    covariance = (vectors * inverse) @ vectors.T
    smallest = singular[-1]
    observability = Observability(
        singular_values=singular,
        condition_number=float(largest / smallest) if smallest > 0 else float("inf"),
        worst_std_mm=float(1.0 / smallest) if smallest > 0 else float("inf"),
        worst_direction=vectors[:, -1].copy(),
        rank=int(np.count_nonzero(determined)),
        undetermined=(vectors[:, ~determined] ** 2).sum(axis=1) > UNDETERMINED_SHARE,
    )
    return covariance, observability


def pose_error_sensitivity(legs: LegModel, pose: Sequence[float], with_scales: bool = False) -> NDArray[np.float64]:
    """S (6, 42), or (6, 48) ``with_scales``: pose error (mm, rad) of a commanded ``pose`` per
    parameter error (mm; scale errors in mm per metre of reading, the parameter vector's unit).

    A controller that uses parameters θ + δθ computes readings r for ``pose``; the platform
    (true θ) then sits at pose + S·δθ to first order: from h(θ, x) = ‖T·P + R − B‖ − zero −
    (1 + s)·r, h(θ, x_true) = h(θ + δθ, x_commanded) gives δx = H_x⁻¹·H_θ·δθ.
    """
    pose = np.asarray(pose, dtype=float)
    pose_jacobian, _ = length_pose_jacobian(legs, pose)
    closure, _ = closure_parameter_jacobian(legs, pose[None, :])
    jacobian = closure[0]
    if with_scales:
        readings = sensor_setpoints_batch(legs, pose[None, :])[0]
        jacobian = np.hstack((jacobian, np.diag(-readings / SCALE_UNIT)))
    return np.linalg.solve(pose_jacobian, jacobian)


@dataclass(frozen=True, slots=True)
class PredictedAccuracy:
    """Pose error expected from a parameter covariance over a set of test motions, per axis.

    ``rms_position_mm``: the RMS over all waypoints and the axes x, y, z of each axis's σ
    (``rms_orientation_deg`` likewise over roll, pitch, yaw). A per-axis figure, not the
    radius √(σx² + σy² + σz²) that :class:`PointAccuracy` (the controller's
    ``predicted_accuracy.position_mm``) gives: √3 · ``rms_position_mm`` is that radius at
    the platform's origin, RMS over the waypoints. ``expected_max_*`` the mean over
    parameter draws of the largest |error| of any waypoint and single axis (the statistic
    the validation reports).
    """

    rms_position_mm: float
    rms_orientation_deg: float
    expected_max_position_mm: float
    expected_max_orientation_deg: float


def predict_accuracy(
    legs: LegModel,
    covariance: NDArray,
    motions: Sequence[TestMotion],
    home_mm_deg: Sequence[float],
    samples: int = 4000,
    seed: int = 0,
) -> PredictedAccuracy:
    """Propagate a parameter covariance (42×42, or 48×48 with scale errors) to the error of
    the motions' commanded poses.

    ``legs`` are the parameters to linearise at (true ones in simulation, identified ones
    otherwise). The expected maxima are Monte-Carlo means over ``samples`` Gaussian
    parameter-error draws (seeded), since a maximum has no closed form.
    """
    relative = np.array([pose for motion in motions for pose in motion.waypoints])
    absolute = absolute_from_relative(home_mm_deg, relative)
    covariance = np.asarray(covariance, dtype=float)
    with_scales = len(covariance) > GEOMETRIC_PARAMETERS
    sensitivity = np.concatenate([pose_error_sensitivity(legs, pose, with_scales) for pose in absolute])  # (6W, p)
    pose_variance = np.einsum("ij,jk,ik->i", sensitivity, covariance, sensitivity).reshape(-1, 6)
    to_deg = np.degrees(1.0)
    # The covariance is PSD by construction (analyse_information), but when some combination
    # is barely determined (variances up to ~1e11 mm²) rounding leaves eigenvalues of about
    # -1e-16 of the largest, which numpy's absolute check (1e-8) reports as "not
    # positive-semidefinite"; its eigh factor uses |eigenvalue|, so they draw ~0 either way.
    draws = np.random.default_rng(seed).multivariate_normal(np.zeros(len(covariance)), covariance, size=samples,
                                                            method="eigh", check_valid="ignore")
    errors = np.abs(draws @ sensitivity.T).reshape(samples, -1, 6)
    return PredictedAccuracy(
        rms_position_mm=float(np.sqrt(np.mean(pose_variance[:, :3]))),
        rms_orientation_deg=float(np.sqrt(np.mean(pose_variance[:, 3:])) * to_deg),
        expected_max_position_mm=float(np.mean(np.max(errors[:, :, :3], axis=(1, 2)))),
        expected_max_orientation_deg=float(np.mean(np.max(errors[:, :, 3:], axis=(1, 2))) * to_deg),
    )


@dataclass(frozen=True, slots=True)
class PointAccuracy:
    """The predicted 1σ error of a point on the platform (the tool point, say), commanded
    to a pose by a controller with uncertain parameters: ``position_mm`` the RMS radius
    √trace Σ (not a per-axis σ: √3 times it when the three are equal), ``position_axes_mm``
    σ along the fixed frame's x, y, z, and ``orientation_deg`` the platform's RMS rotation
    angle √trace Σ_ω (of the small rotation vector, not of roll, pitch, yaw one by one)."""

    position_mm: float
    position_axes_mm: tuple[float, float, float]
    orientation_deg: float


def point_accuracy(legs: LegModel, covariance: NDArray, pose: Sequence[float],
                   point_mm: Sequence[float] = (0.0, 0.0, 0.0)) -> PointAccuracy:
    """Propagate a parameter covariance (42×42, or 48×48 with scale errors; mm², the
    parameter vector's units) to the error of ``point_mm`` (platform frame, mm) with the
    platform commanded to ``pose`` (absolute, mm and rad), to first order: one 6×6 solve.

    With ω = E·δ(roll, pitch, yaw) the small rotation error (fixed frame) and q = T·point,
    the point moves by δR + ω × q.
    """
    pose = np.asarray(pose, dtype=float)
    covariance = np.asarray(covariance, dtype=float)
    sensitivity = pose_error_sensitivity(legs, pose, len(covariance) > GEOMETRIC_PARAMETERS)
    rates = angular_velocity_matrix(pose[4], pose[5])
    rotation = rotation_matrices(pose[3:4], pose[4:5], pose[5:6])[0]
    qx, qy, qz = rotation @ np.asarray(point_mm, dtype=float)
    skew = np.array([[0.0, -qz, qy], [qz, 0.0, -qx], [-qy, qx, 0.0]])
    to_point = np.zeros((6, 6))
    to_point[:3, :3] = np.eye(3)
    to_point[:3, 3:] = -skew @ rates  # ω × q = −[q]×·ω
    to_point[3:, 3:] = rates
    mapped = to_point @ sensitivity
    error = mapped @ covariance @ mapped.T
    variances = np.clip(np.diag(error), 0.0, None)
    return PointAccuracy(
        position_mm=float(np.sqrt(variances[:3].sum())),
        position_axes_mm=(float(np.sqrt(variances[0])), float(np.sqrt(variances[1])), float(np.sqrt(variances[2]))),
        orientation_deg=float(np.degrees(np.sqrt(variances[3:].sum()))),
    )


def pose_fit_noise_rms(poses: NDArray, feature_points_mm: NDArray, point_sigma_mm: float) -> tuple[float, float]:
    """RMS per axis of the error of a pose fitted to ``feature_points_mm`` (K, 3) measured
    with noise ``point_sigma_mm`` per coordinate, over (N, 6) absolute poses (mm, rad):
    (position mm, orientation deg). What an instrument adds to a measured pose error."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    covariance = point_fit_twist_covariance(rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5]),
                                            feature_points_mm, point_sigma_mm)
    variances = np.einsum("nii->ni", covariance)
    return float(np.sqrt(np.mean(variances[:, :3]))), float(np.degrees(np.sqrt(np.mean(variances[:, 3:]))))
