"""Uncertainty: the information of a subset of readings, and the error propagation behind the CRB."""

from __future__ import annotations

import numpy as np

from hexactl.calibration.identification import identify
from hexactl.calibration.parameters import StructuralParameters, calibrated_geometry
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS, X_SWEEP
from hexactl.calibration.uncertainty import (
    analyse_information,
    fisher_information,
    point_accuracy,
    pose_error_sensitivity,
    predict_accuracy,
)
from hexactl.kinematics.geometry import CalibrationInfo
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.sim.offline_campaign import execute_motion


def test_leglock_uncertainty_is_the_bound_of_the_locked_readings(nominal, true_platform, leglock_campaign):
    data = leglock_campaign.data
    feature_points = np.array(nominal.measurement.feature_points)
    sigma, reading = nominal.measurement.point_sigma_mm, IdentificationOptions().reading_sigma_mm
    locked = data.locked_leg[:, None] == np.arange(1, 7)[None, :]
    everything = fisher_information(true_platform.legs, leglock_campaign.true_poses, feature_points, sigma, reading)
    locked_only = fisher_information(true_platform.legs, leglock_campaign.true_poses, feature_points, sigma, reading,
                                     used_readings=locked)
    # Less data, less information: the difference is positive semi-definite.
    assert np.min(np.linalg.eigvalsh(everything - locked_only)) > -1e-6 * np.max(np.linalg.eigvalsh(everything))
    # Each leg's block is informed by its own locked postures only.
    assert np.allclose(locked_only[0:7, 7:14], 0.0, atol=1e-9 * np.max(np.abs(locked_only)))
    result = identify(data, nominal, IdentificationOptions(method=Method.LEGLOCK))
    bound, _ = analyse_information(locked_only)
    ratio = np.sqrt(np.diag(result.covariance)) / np.sqrt(np.diag(bound))
    assert np.all((ratio > 0.85) & (ratio < 1.2))  # weights at the nominal, not the true, joints


def test_sensitivity_predicts_the_pose_error_of_a_slightly_wrong_controller(nominal, true_platform):
    rng = np.random.default_rng(3)
    truth = StructuralParameters.from_geometry(true_platform).to_vector()
    error = rng.normal(0.0, 0.05, truth.size)  # mm: small enough to stay linear
    wrong = StructuralParameters.from_vector(truth + error, with_scales=False)
    info = CalibrationInfo(method="test", created="now", input_sha256="", postures=1, residual_rms_mm=0.0)
    controller = calibrated_geometry(true_platform, wrong, info)
    achieved = execute_motion(controller, true_platform, X_SWEEP).errors
    predicted = np.array([pose_error_sensitivity(true_platform.legs, pose) @ error
                          for pose in absolute_from_relative(true_platform.home, np.array(X_SWEEP.waypoints))])
    predicted[:, 3:] = np.degrees(predicted[:, 3:])
    assert np.max(np.abs(achieved - predicted)) < 1e-3 * np.max(np.abs(achieved))


def test_predicted_accuracy_scales_with_the_covariance(nominal, true_platform):
    covariance = np.diag(np.full(42, 0.01))
    small = predict_accuracy(true_platform.legs, covariance, PAPER_TEST_MOTIONS, nominal.home, samples=500)
    large = predict_accuracy(true_platform.legs, 4 * covariance, PAPER_TEST_MOTIONS, nominal.home, samples=500)
    assert np.isclose(large.rms_position_mm, 2 * small.rms_position_mm)
    assert np.isclose(large.expected_max_orientation_deg, 2 * small.expected_max_orientation_deg)
    assert small.expected_max_position_mm > small.rms_position_mm > 0


def test_the_reports_per_axis_figure_is_the_controllers_radius_over_root_three(nominal, true_platform):
    """The report's predicted pose uncertainty is per axis; status's predicted_accuracy.position_mm
    is a radius. The report states the radius as √3 times its figure: this pins that."""
    covariance = np.diag(np.linspace(0.001, 0.02, 42))
    predicted = predict_accuracy(true_platform.legs, covariance, PAPER_TEST_MOTIONS, nominal.home, samples=10)
    poses = absolute_from_relative(nominal.home, np.array([pose for motion in PAPER_TEST_MOTIONS
                                                            for pose in motion.waypoints]))
    radii = np.array([point_accuracy(true_platform.legs, covariance, pose).position_mm for pose in poses])
    assert np.isclose(np.sqrt(3.0) * predicted.rms_position_mm, np.sqrt(np.mean(radii**2)), rtol=1e-9)
