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
