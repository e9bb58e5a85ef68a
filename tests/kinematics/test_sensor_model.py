"""The sensor model: leg length = zero + (1 + e)·reading, applied wherever a reading meets a length."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.geometry import GeometryError, geometry_from_mapping
from hexactl.kinematics.inverse import (
    leg_length_of_reading, leg_lengths, lengths_from_readings, readings_from_lengths, sensor_setpoints,
    sensor_setpoints_batch,
)
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.workspace import assess_readings
from tests.kinematics.strategies import relative_poses

scale_errors = st.lists(st.floats(-0.005, 0.005, allow_nan=False), min_size=6, max_size=6)


def _with_scales(nominal, errors):
    return geometry_from_mapping({**nominal.model_dump(), "sensor_scale_errors": errors}, "test")


@settings(max_examples=60, deadline=None)
@given(relative_poses(0.5), scale_errors)
def test_setpoints_of_a_geometry_with_gains_give_back_the_pose(nominal, pose_rel, errors) -> None:
    geometry = _with_scales(nominal, errors)
    pose = absolute_from_relative(geometry.home, pose_rel)
    readings = sensor_setpoints(geometry.legs, pose)
    lengths = leg_lengths(geometry.legs, pose)
    expected = (np.array(lengths) - np.array(geometry.zero_lengths)) / (1.0 + np.array(errors))
    assert np.allclose(readings, expected, atol=1e-9)
    assert np.allclose(sensor_setpoints_batch(geometry.legs, np.array([pose]))[0], readings, atol=1e-9)
    assert np.allclose(lengths_from_readings(geometry.legs, readings), lengths, atol=1e-9)
    assert np.allclose(readings_from_lengths(geometry.legs, lengths), readings, atol=1e-9)
    result = forward_kinematics(geometry.legs, lengths_from_readings(geometry.legs, readings).tolist(), geometry.home.in_radians())
    assert result.ok and np.allclose(result.pose, pose, atol=1e-7)


def test_one_leg_alone_follows_the_same_rule(nominal) -> None:
    geometry = _with_scales(nominal, [0.001, -0.002, 0.0, 0.003, 0.0, -0.001])
    readings = np.array([10.0, -20.0, 5.0, 7.5, 0.0, 3.0])
    every = lengths_from_readings(geometry.legs, readings)
    for leg in range(6):
        assert float(lengths_from_readings(geometry.legs, readings[leg], leg)) == pytest.approx(every[leg], abs=1e-12)
        assert leg_length_of_reading(geometry.legs, leg, readings[leg]) == pytest.approx(every[leg], abs=1e-12)
        assert float(readings_from_lengths(geometry.legs, every[leg], leg)) == pytest.approx(readings[leg], abs=1e-12)


def test_a_gain_changes_the_readings_the_limits_check(nominal) -> None:
    """Stroke limits are the sensor's: with a gain above 1 a leg needs a smaller reading."""
    gained = _with_scales(nominal, [0.005] * 6)
    pose = [0.0, 0.0, 100.0, 0.0, 0.0, 0.0]
    plain = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, pose))
    scaled = sensor_setpoints(gained.legs, absolute_from_relative(gained.home, pose))
    assert all(abs(s) < abs(p) for s, p in zip(scaled, plain) if abs(p) > 1.0)
    assessed = assess_readings(gained, [scaled], [0.0] * 6)[0]
    assert assessed is not None and np.allclose(assessed.pose_relative, pose, atol=1e-6)
    assert np.allclose(assessed.sensor_mm, scaled, atol=1e-6)  # what the stroke limits are checked on


def test_an_implausible_gain_is_refused_naming_the_leg(nominal) -> None:
    with pytest.raises(GeometryError, match=r"sensor_scale_errors: leg 3 .*beyond ±0.01"):
        _with_scales(nominal, [0.0, 0.0, 0.02, 0.0, 0.0, 0.0])


def test_older_files_scale_errors_under_calibration_move_to_the_model(nominal) -> None:
    """Files written before the kinematics applied gains kept them in [calibration]."""
    document = nominal.model_dump()
    del document["sensor_scale_errors"]  # an older file has no such key
    document["calibration"] = {"method": "full", "created": "2026-01-01T00:00:00Z", "input_sha256": "0" * 64,
                               "postures": 60, "residual_rms_mm": 0.1,
                               "sensor_scale_errors": [1e-4, 0.0, 0.0, 0.0, 0.0, -2e-4]}
    geometry = geometry_from_mapping(document, "older file")
    assert geometry.sensor_scale_errors == (1e-4, 0.0, 0.0, 0.0, 0.0, -2e-4)
    assert np.allclose(geometry.legs.sensor_gains, [1.0001, 1, 1, 1, 1, 0.9998])
    with pytest.raises(GeometryError, match="sensor_scale_errors and calibration.sensor_scale_errors differ"):
        geometry_from_mapping({**document, "sensor_scale_errors": [0.0] * 6}, "conflicting file")
