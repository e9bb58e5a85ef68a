"""What a user is told about data that cannot calibrate as they are: the true count of
undetermined combinations, and poses in the wrong units named as such."""

from __future__ import annotations

import numpy as np

from hexactl.calibration.data import MeasurementData, measured_poses, screen_measurements
from hexactl.calibration.identification import identify
from hexactl.calibration.results import IdentificationStatus


def test_a_single_posture_measured_again_and_again_leaves_36_combinations_undetermined(nominal, leglock_campaign):
    """One posture determines six combinations (one closure per leg), however often it is
    measured: noise must not pass for information."""
    data, count = leglock_campaign.data, 20
    noise = np.random.default_rng(0).normal(0.0, 0.25, (count, 3, 3))
    repeated = MeasurementData(np.repeat(data.locked_leg[:1], count), np.repeat(data.readings_mm[:1], count, axis=0),
                               np.arange(1, count + 1), points_mm=np.repeat(data.points_mm[:1], count, axis=0) + noise)
    result = identify(repeated, nominal)
    assert result.status is IdentificationStatus.NOT_OBSERVABLE
    assert "the data cannot determine 36 parameter combination(s)" in result.warnings[0]


def _pose_rows(nominal, data, translation_factor=1.0, angle_factor=1.0):
    poses = np.array(measured_poses(data, np.array(nominal.measurement.feature_points)).poses)
    poses[:, :3] *= translation_factor
    poses[:, 3:] *= angle_factor
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, poses=poses)


def test_poses_in_radians_or_metres_are_named_as_a_unit_problem(nominal, leglock_campaign):
    points = np.array(nominal.measurement.feature_points)
    good = _pose_rows(nominal, leglock_campaign.data)
    assert screen_measurements(good, points, 0.25, legs=nominal.legs) == ()
    # A file written in radians is read as degrees: every angle π/180 of what it was.
    radians = screen_measurements(_pose_rows(nominal, leglock_campaign.data, angle_factor=np.pi / 180), points, 0.25,
                                  legs=nominal.legs)
    assert len(radians) == 1 and radians[0].line == 0 and "if the angles are radians" in radians[0].message
    metres = screen_measurements(_pose_rows(nominal, leglock_campaign.data, translation_factor=1e-3), points, 0.25,
                                 legs=nominal.legs)
    assert len(metres) == 1 and "if the positions are metres" in metres[0].message and "convert the file" in metres[0].message


def test_a_mis_sighted_point_goes_to_full_which_excludes_it_and_stops_the_methods_that_cannot(tmp_path, nominal,
                                                                                            leglock_campaign, capsys):
    from hexactl.adapters.cli.main import main
    from hexactl.adapters.files.measurements import write_measurements
    from tests.calibration.conftest import NOMINAL_PATH

    data = leglock_campaign.data
    points = np.array(data.points_mm)
    points[7, 1] += [12.0, -5.0, 0.0]  # in the platform's plane: the distance screening sees it
    path = write_measurements(tmp_path / "mis.csv", MeasurementData(data.locked_leg, data.readings_mm, data.lines,
                                                                     points_mm=points))
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]) == 0
    captured = capsys.readouterr()
    line = int(data.lines[7]) + 1  # the file's header line comes first
    assert f"line {line}: distance p1-p2" in captured.err and "left to full" in captured.err
    assert f"excluded as a mis-sighting: line {line}: feature point p2 off by" in captured.out
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "leglock.toml"),
                 "--method", "leglock"]) == 2
    assert "--skip-bad-rows" in capsys.readouterr().err
