"""Sensor gains: identified when the data show them, written to the calibration file and
applied by the controller's kinematics, so the platform is driven as accurately as one with
exact sensors."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, parse_geometry
from hexactl.adapters.files.measurements import read_measurements
from hexactl.calibration.identification import calibration_geometry, calibration_info, identify
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.sim.offline_campaign import run_offline_campaign, validate_geometry
from hexactl.sim.true_platform import ManufacturingErrors, true_geometry
from tests.calibration.conftest import SMALL

LEAD_ERRORS = ManufacturingErrors(sensor_scale_sigma=5e-4)  # a ball screw's lead error, as the judge used
DEMO_MEASUREMENTS = Path(__file__).parent / "data" / "demo_seed0_measurements.csv"
"""What ``hexactl demo`` (seed 0) measured: 18 leg-lock postures of a platform whose sensors
are exact, with a feature point (line 10's p1) seen 1.5 mm off, close to the cut for gross errors."""


def _calibrated(controller, result):
    return calibration_geometry(controller, result, calibration_info(result, "2026-11-23T00:00:00Z", "0" * 64, "test"))


def _worst_position_error_mm(controller, true) -> float:
    return max(float(np.max(np.abs(motion.errors[:, :3]))) for motion in validate_geometry(controller, true))


@pytest.fixture(scope="module")
def gained(nominal):
    return true_geometry(nominal, seed=5, errors=LEAD_ERRORS)


@pytest.fixture(scope="module")
def baseline_error_mm(nominal, true_platform) -> float:
    """Exact sensors: the accuracy auto reaches on this campaign design."""
    result = identify(run_offline_campaign(nominal, true_platform, SMALL).data, nominal)
    assert result.ok and not result.parameters.has_scales  # no gains invented for exact sensors
    return _worst_position_error_mm(_calibrated(nominal, result), true_platform)


def test_auto_identifies_gains_and_the_calibrated_controller_is_as_accurate_as_with_exact_sensors(
        nominal, gained, baseline_error_mm):
    result = identify(run_offline_campaign(nominal, gained, SMALL).data, nominal)
    assert result.ok and result.parameters.has_scales and "sensor scale errors identified" in result.reason
    calibrated = _calibrated(nominal, result)
    truth, std = np.array(gained.sensor_scale_errors), np.array(calibrated.calibration.sensor_scale_errors_std)
    assert np.all(np.abs(np.array(calibrated.sensor_scale_errors) - truth) < 4 * std)
    assert _worst_position_error_mm(calibrated, gained) < 1.25 * baseline_error_mm
    ignored = identify(run_offline_campaign(nominal, gained, SMALL).data, nominal, IdentificationOptions(method=Method.FULL))
    assert _worst_position_error_mm(_calibrated(nominal, ignored), gained) > 2 * baseline_error_mm


def test_the_calibration_file_carries_the_gains_and_loads_them_into_the_kinematics(nominal, gained):
    result = identify(run_offline_campaign(nominal, gained, SMALL).data, nominal)
    calibrated = _calibrated(nominal, result)
    text = geometry_to_toml(calibrated)
    assert text.startswith("name") and "\nsensor_scale_errors = [" in text and "sensor_scale_errors_std = [" in text
    loaded = parse_geometry(text, "calibration.toml")
    assert np.array_equal(loaded.legs.sensor_gains, 1.0 + np.array(calibrated.sensor_scale_errors))
    assert geometry_id(loaded) == geometry_id(calibrated)


def test_keys_added_to_the_format_are_left_out_at_their_defaults(nominal):
    """Exact sensors and exactly known feature points: files and ids stay as they were."""
    text = geometry_to_toml(nominal)
    assert "sensor_scale_errors" not in text and "feature_point_sigma_mm" not in text
    older = nominal.model_dump(mode="json")  # as a geometry was before those keys existed
    del older["sensor_scale_errors"], older["measurement"]["feature_point_sigma_mm"]
    canonical = json.dumps(older, sort_keys=True, separators=(",", ":"))
    assert geometry_id(nominal) == hashlib.sha256(canonical.encode("utf-8")).hexdigest()[:16]


def test_a_recalibration_starts_from_the_gains_it_is_given(nominal, gained):
    """Redoing a calibration from a calibrated file keeps its gains (without --scales) or
    refines them (with): the readings are taken through the starting geometry's gains."""
    first = _calibrated(nominal, identify(run_offline_campaign(nominal, gained, SMALL).data, nominal))
    data = run_offline_campaign(first, gained, SMALL).data
    kept = identify(data, first, IdentificationOptions(method=Method.FULL))
    assert not kept.parameters.has_scales
    again = _calibrated(first, kept)
    assert again.sensor_scale_errors == first.sensor_scale_errors
    assert _worst_position_error_mm(again, gained) < 0.5 * _worst_position_error_mm(
        _calibrated(nominal, identify(data, nominal, IdentificationOptions(method=Method.FULL))), gained)
    # Refined: the same estimate as from the nominal (exact sensors), whatever gains it starts from.
    scales = IdentificationOptions(method=Method.FULL, estimate_scales=True)
    refined, direct = _calibrated(first, identify(data, first, scales)), _calibrated(nominal, identify(data, nominal, scales))
    assert np.allclose(refined.sensor_scale_errors, direct.sensor_scale_errors, atol=1e-8)
    assert np.allclose(refined.zero_lengths, direct.zero_lengths, atol=1e-4)
    std = np.array(refined.calibration.sensor_scale_errors_std)
    assert np.all(np.abs(np.array(refined.sensor_scale_errors) - np.array(gained.sensor_scale_errors)) < 4 * std)


def test_the_report_compares_identified_gains_with_the_nominals_and_the_true_ones(nominal, gained, tmp_path):
    """A recalibration from a file with gains: the report's nominal column holds that file's
    gains (it read 0, and the deviation was the whole gain), and with the truth known each
    gain's true error is given, as for every other parameter."""
    from hexactl.adapters.report.html import CalibrationReport, write_report

    first = _calibrated(nominal, identify(run_offline_campaign(nominal, gained, SMALL).data, nominal))
    result = identify(run_offline_campaign(first, gained, SMALL).data, first,
                      IdentificationOptions(method=Method.FULL, estimate_scales=True))
    page = write_report(tmp_path, CalibrationReport("data.csv", "now", first, result, true=gained)).read_text("utf-8")
    for leg in range(6):
        cells = re.search(rf"<th class='l'>scale{leg + 1}</th>((?:<td>[^<]*</td>)+)</tr>", page).group(1)
        nominal_gain, identified, deviation, _, true_error, _ = map(float, re.findall(r"<td>([^<]*)</td>", cells))
        assert nominal_gain == pytest.approx(1000 * first.sensor_scale_errors[leg], abs=1e-3)
        assert deviation == pytest.approx(identified - nominal_gain, abs=2e-3)
        assert true_error == pytest.approx(1000 * (gained.sensor_scale_errors[leg] - result.parameters.scale_errors[leg]),
                                           abs=1e-3)


def test_the_simulated_platform_with_gains_moves_by_its_true_sensor_model(nominal, gained):
    """The simulator's physical platform turns the drives' readings into lengths by the true
    gains: the calibrated controller's set-points put it where commanded, the nominal's do not."""
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.kinematics.pose import absolute_from_relative
    from hexactl.sim.physical_platform import PhysicalPlatform

    pose = absolute_from_relative(gained.home, [40.0, -30.0, 60.0, 2.0, -1.0, 5.0])
    exact = true_geometry(nominal, seed=5)  # the same joints and zero lengths, exact sensors
    readings = sensor_setpoints(gained.legs, pose)
    assert PhysicalPlatform(gained, lambda: readings).true_pose().absolute == pytest.approx(pose, abs=1e-6)
    ignored = PhysicalPlatform(gained, lambda: sensor_setpoints(exact.legs, pose)).true_pose().absolute
    assert np.max(np.abs(np.subtract(ignored[:3], pose[:3]))) > 0.01


def test_full_without_scales_warns_that_the_data_show_gains(nominal, gained):
    result = identify(run_offline_campaign(nominal, gained, SMALL).data, nominal, IdentificationOptions(method=Method.FULL))
    assert not result.parameters.has_scales
    assert any("the data show sensor scale errors" in warning and "--scales" in warning for warning in result.warnings)


def test_a_mis_sighting_only_the_fit_with_gains_excludes_is_not_taken_for_gains(nominal):
    # The fit with gains excluded that point and the fit without kept it: their χ² differed
    # by the point's share too, 29.5 in all, and gains were identified (auto) or said to be
    # in the data (full). Compared on the same observations they are not significant.
    data = read_measurements(DEMO_MEASUREMENTS, len(nominal.measurement.feature_points)).data
    with_gains = identify(data, nominal, IdentificationOptions(method=Method.FULL, estimate_scales=True))
    without = identify(data, nominal, IdentificationOptions(method=Method.FULL))
    assert [(observation.line, observation.point) for observation in with_gains.excluded] == [(10, 1)]
    assert without.excluded == ()
    assert not any("sensor scale errors" in warning for warning in without.warnings), without.warnings
    chosen = identify(data, nominal)  # auto
    assert chosen.ok and not chosen.parameters.has_scales, chosen.reason
