"""Predicted accuracy on every move: validate_pose's answer, status's figure for the
commanded pose, and a move's tolerance (refused ``accuracy_insufficient``)."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.calibration.uncertainty import point_accuracy
from hexactl.control.frames import OperatorFrames
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.pose import absolute_from_relative

GOAL = [20.0, -10.0, 30.0, 2.0, 1.0, -3.0]


@pytest.fixture
def with_covariance(geometry) -> Geometry:
    """The rig's geometry with a calibration table carrying a parameter covariance."""
    factor = np.random.default_rng(3).normal(0.0, 0.02, (42, 42))
    calibration = {"method": "full", "created": "2026-11-23T00:00:00Z", "input_sha256": "0" * 64, "postures": 60,
                   "residual_rms_mm": 0.2, "parameter_covariance": (factor @ factor.T).tolist()}
    return Geometry.model_validate({**geometry.model_dump(), "calibration": calibration})


def test_validate_pose_predicts_the_error_at_the_tool_point_on_arrival(rig, with_covariance):
    rig.enabled()
    assert rig.controller.load_calibration(with_covariance, "cal-1").ok
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    tool = [0.0, 0.0, 300.0, 0.0, 0.0, 0.0]
    assert rig.controller.set_frames(OperatorFrames(tool=tool)).ok
    result = rig.controller.validate_pose(GOAL)
    assert result.ok
    expected = point_accuracy(with_covariance.legs, np.array(with_covariance.calibration.parameter_covariance),
                              absolute_from_relative(with_covariance.home, GOAL), tool[:3])
    accuracy = result.details["predicted_accuracy"]
    assert accuracy["position_mm"] == pytest.approx(expected.position_mm, rel=1e-12)
    assert accuracy["orientation_deg"] == pytest.approx(expected.orientation_deg, rel=1e-12)
    assert accuracy["tool_point_mm"] == tool[:3]
    # status's figure is for the commanded pose now (the zero posture)
    now = rig.controller.predicted_accuracy()
    at_zero = point_accuracy(with_covariance.legs, np.array(with_covariance.calibration.parameter_covariance),
                             with_covariance.home.in_radians(), tool[:3])
    assert now["position_mm"] == pytest.approx(at_zero.position_mm, rel=1e-9)


def test_a_move_whose_prediction_exceeds_its_tolerance_is_refused_and_moves_nothing(rig, with_covariance):
    rig.enabled()
    assert rig.controller.load_calibration(with_covariance, "cal-1").ok
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    predicted = rig.controller.validate_pose(GOAL).details["predicted_accuracy"]["position_mm"]
    refused = rig.controller.move(GOAL, tolerance_mm=0.5 * predicted)
    assert not refused.ok and refused.error.value == "accuracy_insufficient"
    assert "exceeds the tolerance" in refused.message and refused.details["predicted_accuracy"]["position_mm"] == predicted
    assert not rig.controller.validate_pose(GOAL, tolerance_mm=0.5 * predicted).ok
    rig.run(20)
    assert list(rig.controller.telemetry().pose_command) == pytest.approx([0.0] * 6, abs=1e-12)
    assert rig.controller.move(GOAL, tolerance_mm=2 * predicted).ok
    rig.settle()
    assert list(rig.controller.telemetry().pose_command) == pytest.approx(GOAL, abs=1e-9)


def test_without_a_covariance_there_is_no_prediction_and_a_tolerance_cannot_be_met(rig):
    rig.enabled()
    assert rig.controller.validate_pose(GOAL).details["predicted_accuracy"] is None
    assert rig.controller.predicted_accuracy() is None
    refused = rig.controller.move(GOAL, tolerance_mm=1.0)
    assert refused.error.value == "accuracy_insufficient" and "no parameter covariance" in refused.message
    assert rig.controller.move(GOAL, tolerance_mm=float("nan")).error.value == "invalid_argument"
