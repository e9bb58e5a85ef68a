"""The simulated platform, instrument and campaign."""

from __future__ import annotations

import numpy as np

from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS
from hexactl.calibration.validation import summarise_validation
from hexactl.kinematics.inverse import leg_lengths_batch
from hexactl.sim.instrument import SimulatedInstrument
from hexactl.sim.offline_campaign import validate_geometry
from hexactl.sim.true_platform import ManufacturingErrors, true_geometry


def test_true_platform_is_seeded_and_sized_as_asked(nominal):
    a, b = true_geometry(nominal, 1), true_geometry(nominal, 1)
    assert a.base_joints == b.base_joints and a.zero_lengths == b.zero_lengths
    errors = np.concatenate([np.subtract(true_geometry(nominal, s).base_joints, nominal.base_joints).ravel()
                             for s in range(30)])
    assert 1.7 < np.std(errors) < 2.3
    exact = true_geometry(nominal, 1, ManufacturingErrors(0.0, 0.0))
    assert exact.platform_joints == nominal.platform_joints


def test_instrument_noise_has_the_configured_sigma(nominal):
    instrument = SimulatedInstrument.for_geometry(nominal, seed=4, point_sigma_mm=0.5)
    pose = (10.0, -20.0, 2000.0, 0.1, -0.05, 0.2)
    exact = SimulatedInstrument.for_geometry(nominal, seed=4, point_sigma_mm=0.0).measure(pose)
    noise = np.array([instrument.measure(pose) - exact for _ in range(400)])
    assert abs(np.std(noise) - 0.5) < 0.03 and abs(np.mean(noise)) < 0.03


def test_campaign_rows_reproduce_the_true_poses(nominal, true_platform, noise_free_campaign):
    data = noise_free_campaign.data
    lengths = leg_lengths_batch(true_platform.legs, noise_free_campaign.true_poses)
    assert np.allclose(lengths - np.array(true_platform.zero_lengths), data.readings_mm, atol=1e-8)
    for leg in range(1, 7):
        rows = data.locked_rows(leg)
        assert len(rows) == 9 and np.ptp(data.readings_mm[rows, leg - 1]) < 1e-9


def test_validation_of_the_nominal_controller_shows_the_manufacturing_errors(nominal, true_platform):
    before = validate_geometry(nominal, true_platform)
    assert [result.motion for result in before] == list(PAPER_TEST_MOTIONS)
    assert summarise_validation(before).max_position_error_mm > 1.0
    assert summarise_validation(validate_geometry(true_platform, true_platform)).max_position_error_mm < 1e-6
