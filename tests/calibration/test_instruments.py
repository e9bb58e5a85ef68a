"""The instruments' own observations: theodolite pairs and laser trackers, their Jacobians,
the points they imply, and calibrations from them with their native noise."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.calibration.observations import LaserTracker, Station, Theodolites, point_covariance, wrapped

ARCSEC = np.radians(1.0 / 3600.0)
THEODOLITES = Theodolites((Station((4000.0, -3000.0, 1500.0, 0.0, 0.0, 140.0)),
                           Station((4000.0, 3000.0, 1500.0, 0.0, 0.0, -140.0))), 2 * ARCSEC)
TRACKER = LaserTracker(Station((-3500.0, 500.0, 1000.0, 0.0, 0.0, 10.0)), 0.015, 1 * ARCSEC)
points = st.tuples(st.floats(-900, 900), st.floats(-900, 900), st.floats(1500, 2600)).map(np.array)


@settings(max_examples=40, deadline=None)
@given(points, st.sampled_from([THEODOLITES, TRACKER]))
def test_the_jacobians_match_finite_differences(point, instrument):
    jacobian = instrument.jacobian(point)
    step = 1e-4
    for axis in range(3):
        delta = np.zeros(3)
        delta[axis] = step
        numeric = wrapped(instrument.predict(point + delta) - instrument.predict(point - delta)) / (2 * step)
        assert np.allclose(jacobian[:, axis], numeric, rtol=1e-5, atol=1e-10)


@settings(max_examples=40, deadline=None)
@given(points, st.sampled_from([THEODOLITES, TRACKER]))
def test_the_observations_give_back_their_point(point, instrument):
    assert np.allclose(instrument.points(instrument.predict(point)), point, atol=1e-6)


def test_the_implied_points_scatter_as_their_covariance_says(rng=np.random.default_rng(0)):
    point = np.array([300.0, -200.0, 2100.0])
    for instrument in (THEODOLITES, TRACKER):
        clean = instrument.predict(point)
        draws = instrument.points(clean + rng.normal(size=(20000, instrument.size)) * instrument.sigmas)
        whitening = np.linalg.inv(np.linalg.cholesky(point_covariance(instrument, point)))
        assert np.allclose(np.cov((draws - point) @ whitening.T, rowvar=False), np.eye(3), atol=0.05)


def test_parallel_rays_cannot_be_triangulated():
    station = Station((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="parallel"):
        Theodolites((station, Station((0.0, 0.0, 100.0, 0.0, 0.0, 0.0))), ARCSEC).points(np.zeros(4))


def test_coincident_stations_are_named_not_triangulated_into_nan():
    """Found in review: both stations at one place gave numpy warnings and points "nan
    from their centre"; each point's rays meet only at the station."""
    station = Station((4000.0, 3000.0, 1500.0, 0.0, 0.0, -140.0))
    observations = THEODOLITES.predict(np.array([[0.0, 0.0, 2000.0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"the two theodolites' stations coincide \(0 mm apart\)"):
            Theodolites((station, station), ARCSEC).points(observations)


def _observed_campaign(nominal, true, instrument, seed, mis_sighted=None):
    """A leg-lock campaign measured by ``instrument``: its angles (and ranges) with their
    native noise, turned into points with their own covariance."""
    from hexactl.calibration.campaign import plan_campaign
    from hexactl.calibration.data import MeasurementData
    from hexactl.calibration.uncertainty import DEFAULT_READING_SIGMA_MM
    from hexactl.kinematics.rotation import rotation_matrices
    from hexactl.sim.instrument import SimulatedInstrument
    from hexactl.sim.offline_campaign import execute_plans
    from tests.calibration.conftest import SMALL

    campaign = execute_plans(nominal, true, plan_campaign(nominal, SMALL), SimulatedInstrument.for_geometry(nominal, seed),
                             DEFAULT_READING_SIGMA_MM, seed)  # the readings' noise the identification assumes
    poses = campaign.true_poses
    true_points = (np.einsum("nij,kj->nki", rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5]),
                             np.array(nominal.measurement.feature_points)) + poses[:, None, :3])
    rng = np.random.default_rng(seed)
    observed = instrument.predict(true_points) + rng.normal(size=true_points.shape[:2] + (instrument.size,)) * instrument.sigmas
    if mis_sighted is not None:  # (row, point, observation, error)
        row, point, which, error = mis_sighted
        observed[row, point, which] += error
    points = instrument.points(observed)
    data = campaign.data
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=points,
                           point_covariance_mm2=point_covariance(instrument, points))


@pytest.mark.parametrize("instrument", [THEODOLITES, TRACKER], ids=["theodolites", "tracker"])
def test_a_campaign_measured_by_the_instrument_calibrates_with_an_honest_prediction(nominal, instrument):
    from hexactl.calibration.identification import identify
    from hexactl.calibration.results import IdentificationOptions, Method
    from hexactl.calibration.validation import summarise_validation
    from hexactl.sim.offline_campaign import validate_geometry
    from hexactl.sim.true_platform import true_geometry
    from tests.calibration.test_sensor_gains import _calibrated

    ratios = []
    for seed in range(4):
        true = true_geometry(nominal, seed)
        result = identify(_observed_campaign(nominal, true, instrument, seed), nominal,
                          IdentificationOptions(method=Method.FULL))
        assert result.ok and 0.6 < result.chi2_per_dof < 1.4
        actual = summarise_validation(validate_geometry(_calibrated(nominal, result), true)).max_position_error_mm
        ratios.append(actual / result.predicted.expected_max_position_mm)
    assert 0.5 < np.mean(ratios) < 2.0, ratios


THEODOLITE_FILE = """kind = "theodolites"
stations = [[4000, -3000, 1500, 0, 0, 140], [4000, 3000, 1500, 0, 0, -140]]
angle_sigma_arcsec = 2.0
"""
TRACKER_FILE = """kind = "tracker"
stations = [[-3500, 500, 1000, 0, 0, 10]]
angle_sigma_arcsec = 1.0
range_sigma_mm = 0.015
"""


@pytest.mark.parametrize("text", [THEODOLITE_FILE, TRACKER_FILE], ids=["theodolites", "tracker"])
def test_simulate_campaign_writes_the_instruments_observations_and_calibrate_reads_them(tmp_path, capsys, text):
    from hexactl.adapters.cli.main import main
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.sim.offline_campaign import validate_geometry
    from hexactl.calibration.validation import summarise_validation
    from tests.calibration.conftest import NOMINAL_PATH

    instrument = tmp_path / "instrument.toml"
    instrument.write_text(text)
    data, true = tmp_path / "data.csv", tmp_path / "true.toml"
    assert main(["simulate-campaign", "--config", str(NOMINAL_PATH), "-o", str(data), "--per-leg", "10",
                 "--instrument", str(instrument), "--true-output", str(true)]) == 0
    header = next(line for line in data.read_text().splitlines() if line.startswith("leg,"))
    assert ("p3_v_b" in header) if "theodolites" in text else ("p3_range" in header)
    assert main(["calibrate", str(data), "--config", str(NOMINAL_PATH), "--instrument", str(instrument),
                 "-o", str(tmp_path / "cal.toml")]) == 0
    assert "status: ok" in capsys.readouterr().out
    summary = summarise_validation(validate_geometry(load_geometry(tmp_path / "cal.toml"), load_geometry(true)))
    assert summary.max_position_error_mm < 0.1  # instruments far finer than the paper's 0.25 mm per coordinate


def test_observation_files_name_what_is_missing_or_wrong(tmp_path, capsys):
    from hexactl.adapters.cli.main import main
    from tests.calibration.conftest import NOMINAL_PATH

    theodolites, tracker = tmp_path / "theodolites.toml", tmp_path / "tracker.toml"
    theodolites.write_text(THEODOLITE_FILE)
    tracker.write_text(TRACKER_FILE)
    data = tmp_path / "data.csv"
    assert main(["simulate-campaign", "--config", str(NOMINAL_PATH), "-o", str(data), "--per-leg", "5",
                 "--instrument", str(theodolites)]) == 0
    capsys.readouterr()
    calibrate = ["calibrate", str(data), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]
    assert main(calibrate) == 2
    assert "the columns hold theodolites observations" in capsys.readouterr().err
    assert main([*calibrate, "--instrument", str(tracker)]) == 2
    assert "the instrument file describes tracker" in capsys.readouterr().err
    broken = tmp_path / "broken.toml"
    broken.write_text(TRACKER_FILE.replace("range_sigma_mm = 0.015\n", ""))
    assert main([*calibrate, "--instrument", str(broken)]) == 2
    assert "range_sigma_mm: a tracker needs it" in capsys.readouterr().err
    same_place = tmp_path / "same.toml"
    same_place.write_text(THEODOLITE_FILE.replace("[4000, -3000, 1500, 0, 0, 140]", "[4000, 3000, 1500, 0, 0, -140]"))
    assert main([*calibrate, "--instrument", str(same_place)]) == 2
    assert (f"{same_place}: stations: the two theodolites stand at the same place (0 mm apart): from one place a "
            "point's two rays meet only at the station and nothing can be triangulated; give each station's own "
            "position") in capsys.readouterr().err
    assert main(["simulate-campaign", "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "x.csv"), "--pose-form",
                 "--instrument", str(tracker)]) == 2
    assert "exclude each other" in capsys.readouterr().err


def test_a_mis_sighted_angle_is_excluded_by_full(nominal):
    from hexactl.calibration.identification import identify
    from hexactl.calibration.results import IdentificationOptions, Method
    from hexactl.sim.true_platform import true_geometry

    data = _observed_campaign(nominal, true_geometry(nominal, 0), THEODOLITES, 0,
                              mis_sighted=(17, 1, 2, np.radians(0.02)))  # station B's horizontal angle of p2
    result = identify(data, nominal, IdentificationOptions(method=Method.FULL))
    assert [(observation.row, observation.point) for observation in result.excluded] == [(17, 2)]
