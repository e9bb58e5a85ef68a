"""A calibration file's covariance checked against its own standard deviations when read.

The controller predicts every move's error from ``[calibration] parameter_covariance``
alone; the ``*_std_mm`` arrays beside it are the square roots of its diagonal. A covariance
zeroed or scaled down by hand (found in review: status then showed an accuracy of 0.000 mm
and any ``move --tolerance`` passed) contradicts them, and the file is refused naming it.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from hexactl.adapters.files.geometry_file import geometry_to_toml, parse_geometry
from hexactl.calibration.identification import calibration_geometry, calibration_info, identify
from hexactl.kinematics.geometry import Geometry, GeometryError


@pytest.fixture(scope="module")
def calibrated(nominal, leglock_campaign):
    """The calibration file hexactl writes for the small campaign, as a mapping to edit."""
    result = identify(leglock_campaign.data, nominal)
    info = calibration_info(result, "2026-01-01T00:00:00+00:00", "0" * 64, nominal.name)
    return calibration_geometry(nominal, result, info).model_dump(mode="json", exclude_none=True)


def _text(document: dict, **calibration) -> str:
    """The file's text with ``calibration``'s keys replaced (None: removed)."""
    table = {**document["calibration"], **calibration}
    table = {key: value for key, value in table.items() if value is not None}
    return geometry_to_toml(Geometry.model_validate({**document, "calibration": table}))


def _refusal(text: str) -> str:
    with pytest.raises(GeometryError) as refused:
        parse_geometry(text, "cal.toml")
    return str(refused.value)


def test_the_written_file_and_one_rounded_by_hand_are_accepted(calibrated):
    assert parse_geometry(_text(calibrated), "cal.toml").calibration.parameter_covariance is not None
    rounded = {key: np.round(np.array(calibrated["calibration"][key]), 3).tolist()
               for key in ("base_joints_std_mm", "platform_joints_std_mm", "zero_lengths_std_mm")}
    parse_geometry(_text(calibrated, **rounded), "cal.toml")


@pytest.mark.parametrize("factor", [0.0, 1e-8], ids=["zeroed", "tiny"])
def test_a_covariance_zeroed_or_scaled_down_is_refused_naming_file_key_and_remedy(calibrated, factor):
    covariance = (np.array(calibrated["calibration"]["parameter_covariance"]) * factor).tolist()
    message = _refusal(_text(calibrated, parameter_covariance=covariance))
    assert message.startswith("cal.toml: calibration.parameter_covariance: its diagonal entry 0 (0-based; per leg "
                              "B x y z, P x y z, zero, then the six gains) gives B1.x a standard deviation of ")
    assert "but calibration.base_joints_std_mm[0][0] says" in message and "(and 41 more parameter(s))" in message
    assert "calibrate again, or restore the file as hexactl calibrate wrote it" in message


def test_one_variance_off_is_named_by_its_parameter_in_the_per_leg_order(calibrated):
    """Per leg B_i, P_i, zero_i: entry 18 is leg 3's P.y (found in review: the order is not
    B for all legs, then P, then the zero lengths)."""
    covariance = np.array(calibrated["calibration"]["parameter_covariance"])
    covariance[18, :] *= 0.9  # its σ 10 % smaller (row and column: still a covariance), beyond rounding
    covariance[:, 18] *= 0.9
    message = _refusal(_text(calibrated, parameter_covariance=covariance.tolist()))
    stated = calibrated["calibration"]["platform_joints_std_mm"][2][1]
    assert re.search(r"its diagonal entry 18 \(.*\) gives P3\.y a standard deviation of [0-9.]+ mm, but "
                     rf"calibration\.platform_joints_std_mm\[2\]\[1\] says {stated:.4g} mm: both", message)


def test_the_gains_variances_are_checked_against_their_dimensionless_deviations(calibrated):
    covariance = np.zeros((48, 48))
    covariance[:42, :42] = calibrated["calibration"]["parameter_covariance"]
    scale_std = [2e-5] * 6  # dimensionless; the covariance holds mm per metre: (0.02)²
    covariance[42:, 42:] = np.diag([0.02**2] * 5 + [0.002**2])
    with_gains = dict(calibrated, sensor_scale_errors=[0.0] * 6)
    assert _refusal(_text(with_gains, parameter_covariance=covariance.tolist(), sensor_scale_errors_std=scale_std)) \
        .count("gives scale6 a standard deviation of 2e-06, but calibration.sensor_scale_errors_std[5] says 2e-05") == 1
    covariance[47, 47] = 0.02**2
    parse_geometry(_text(with_gains, parameter_covariance=covariance.tolist(), sensor_scale_errors_std=scale_std),
                   "cal.toml")


def test_a_covariance_without_its_standard_deviations_is_refused(calibrated):
    message = _refusal(_text(calibrated, zero_lengths_std_mm=None))
    assert "parameter_covariance: given without base_joints_std_mm" in message and "calibrate again" in message
