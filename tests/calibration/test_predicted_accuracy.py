"""Predicted accuracy at a point on the platform, from a calibration's parameter covariance:
the propagation's properties, and agreement with the spread of repeated calibrations."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.calibration.campaign import plan_campaign
from hexactl.calibration.identification import identify
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.calibration.uncertainty import point_accuracy, pose_error_sensitivity
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.inverse import lengths_from_readings, sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_matrix
from hexactl.sim.instrument import SimulatedInstrument
from hexactl.sim.offline_campaign import execute_plans
from tests.calibration.conftest import SMALL

POSES = ([0, 0, 0, 0, 0, 0], [300, -200, 100, 10, -5, 20], [-400, 100, -150, -15, 10, -30])
TOOL_POINT = np.array([100.0, 50.0, 300.0])
points = st.tuples(*(st.floats(-500, 500, allow_nan=False),) * 3)


def _covariance(seed: int, size: int = 42) -> np.ndarray:
    factor = np.random.default_rng(seed).normal(0.0, 0.05, (size, size))
    return factor @ factor.T


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 1000), points, st.floats(0.1, 100.0))
def test_the_prediction_scales_with_the_covariance_and_is_zero_without_one(true_platform, seed, point, scale):
    pose = true_platform.home.in_radians()
    covariance = _covariance(seed)
    base = point_accuracy(true_platform.legs, covariance, pose, point)
    scaled = point_accuracy(true_platform.legs, scale * covariance, pose, point)
    assert scaled.position_mm == pytest.approx(np.sqrt(scale) * base.position_mm, rel=1e-9)
    assert scaled.orientation_deg == pytest.approx(np.sqrt(scale) * base.orientation_deg, rel=1e-9)
    assert base.position_mm == pytest.approx(np.linalg.norm(base.position_axes_mm), rel=1e-12)
    zero = point_accuracy(true_platform.legs, np.zeros((42, 42)), pose, point)
    assert zero.position_mm == 0.0 and zero.orientation_deg == 0.0


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 1000))
def test_at_the_platform_origin_it_is_the_poses_own_translation_error(true_platform, seed):
    pose = absolute_from_relative(true_platform.home, POSES[1])
    covariance = _covariance(seed, 48)
    sensitivity = pose_error_sensitivity(true_platform.legs, pose, with_scales=True)
    translation = sensitivity[:3] @ covariance @ sensitivity[:3].T
    accuracy = point_accuracy(true_platform.legs, covariance, pose)
    assert accuracy.position_axes_mm == pytest.approx(np.sqrt(np.diag(translation)), rel=1e-9)


def test_it_matches_the_spread_of_repeated_calibrations_within_20_percent(nominal, true_platform):
    """100 campaigns of one platform with fresh noise: the tool point's actual error when
    each calibration drives the platform, against the prediction from the covariances."""
    plans = plan_campaign(nominal, SMALL)
    poses = [absolute_from_relative(nominal.home, pose) for pose in POSES]
    errors, predicted = [], []
    for seed in range(100):
        campaign = execute_plans(nominal, true_platform, plans, SimulatedInstrument.for_geometry(nominal, 1000 + seed),
                                 0.01, 2000 + seed)
        result = identify(campaign.data, nominal, IdentificationOptions(method=Method.FULL))
        legs = result.parameters.legs()
        row = []
        for pose in poses:
            reached = forward_kinematics(true_platform.legs, lengths_from_readings(
                true_platform.legs, sensor_setpoints(legs, pose)).tolist(), pose)
            assert reached.ok
            row.append(_tool_point(reached.pose) - _tool_point(pose))
        errors.append(row)
        predicted.append([point_accuracy(legs, result.covariance, pose, TOOL_POINT).position_mm for pose in poses])
    actual = np.sqrt(np.mean(np.sum(np.array(errors) ** 2, axis=2), axis=0))
    ratio = actual / np.median(predicted, axis=0)
    assert np.all((0.8 < ratio) & (ratio < 1.2)), ratio


def _tool_point(pose) -> np.ndarray:
    return rotation_matrix(*pose[3:]) @ TOOL_POINT + np.asarray(pose[:3])
