"""The washout filter: each channel's behaviour, the sign conventions, the tilt limits, the
streaming and batch forms, and the specific force a pose trajectory makes felt."""

from __future__ import annotations

from math import asin, cos, degrees, radians, sin

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from hexactl.cueing.parameters import (
    CueingParameters,
    RotationalChannel,
    TiltCoordination,
    TranslationalChannel,
)
from hexactl.cueing.washout import (
    GRAVITY_M_S2,
    VehicleTrajectory,
    WashoutFilter,
    perceived_specific_force,
    rms_difference,
    wash_out,
)
from hexactl.kinematics.axes import RelativeMmDeg
from hexactl.kinematics.rotation import rotation_matrix

PERIOD_S = 0.01
AT_REST = (0.0, 0.0, GRAVITY_M_S2)
NO_TILT = CueingParameters(tilt=TiltCoordination(gain=(0.0, 0.0)))


def run(parameters: CueingParameters, forces, rates=None, period_s: float = PERIOD_S) -> np.ndarray:
    """(N, 6) poses for (N, 3) specific forces and angular rates (default none), from rest."""
    forces = np.asarray(forces, dtype=float)
    rates = np.zeros_like(forces) if rates is None else np.asarray(rates, dtype=float)
    washout = WashoutFilter(parameters, period_s)
    return np.array([washout.step(force, rate) for force, rate in zip(forces.tolist(), rates.tolist())])


def sustained(force=AT_REST, seconds: float = 60.0, rest_s: float = 1.0) -> np.ndarray:
    """Specific forces: at rest for ``rest_s``, then ``force`` for the rest of ``seconds``."""
    samples = round(seconds / PERIOD_S)
    forces = np.tile(AT_REST, (samples, 1))
    forces[round(rest_s / PERIOD_S):] = force
    return forces


def test_a_vehicle_at_rest_leaves_the_platform_at_the_zero_posture_exactly() -> None:
    washout = WashoutFilter(CueingParameters(), PERIOD_S)
    poses = {washout.step(AT_REST, (0.0, 0.0, 0.0)) for _ in range(1000)}
    assert poses == {RelativeMmDeg(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)}


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["x", "y", "z"])
def test_a_sustained_specific_force_moves_the_platform_then_washes_out_to_the_zero_position(axis: int) -> None:
    force = np.array(AT_REST)
    force[axis] += 2.0
    poses = run(NO_TILT, sustained(force))
    travel = poses[:, axis]
    assert travel.max() > 50.0  # mm, toward the force: the onset cue
    assert abs(travel[-1]) < 0.5  # mm, back at the zero posture while the force lasts
    others = [a for a in range(6) if a != axis]
    assert np.all(poses[:, others] == 0.0)


def test_the_onset_cue_is_the_specific_force_the_platform_makes_felt_at_first() -> None:
    poses = run(NO_TILT, sustained((2.0, 0.0, GRAVITY_M_S2)))
    felt = perceived_specific_force(poses, PERIOD_S)
    gain = NO_TILT.translational.gain[0]
    step = round(1.0 / PERIOD_S)
    assert felt[step:step + 10, 0].max() == pytest.approx(gain * 2.0, rel=0.05)  # the high-pass passes the jump
    assert abs(felt[-1, 0]) < 0.01  # washed out: the sustained part is the tilt's job


def test_a_second_order_high_pass_leaves_the_platform_displaced() -> None:
    translational = TranslationalChannel(washout_rad_s=(0.0, 0.0, 0.0))
    poses = run(CueingParameters(translational=translational, tilt=NO_TILT.tilt), sustained((2.0, 0.0, GRAVITY_M_S2)))
    expected_mm = translational.gain[0] * 2.0 / translational.break_rad_s[0] ** 2 * 1000.0
    assert poses[-1, 0] == pytest.approx(expected_mm, rel=1e-3)


def test_a_forward_specific_force_tilts_the_nose_up_so_gravity_pushes_the_occupant_back() -> None:
    forward = 2.0  # m/s², below the tilt limit's g·sin(15°) = 2.54
    poses = run(CueingParameters(), sustained((forward, 0.0, GRAVITY_M_S2)))
    pitch = poses[-1, 4]
    assert pitch == pytest.approx(-degrees(asin(forward / GRAVITY_M_S2)), abs=1e-6)
    nose = rotation_matrix(0.0, radians(pitch), 0.0) @ np.array([1.0, 0.0, 0.0])
    assert nose[2] > 0  # hexactl's pitch: positive tips +x down, so a forward force's is negative
    felt = perceived_specific_force(poses, PERIOD_S)[-1]
    np.testing.assert_allclose(felt[:2], [forward, 0.0], atol=1e-6)  # sustained: the tilt reproduces it


def test_a_leftward_specific_force_rolls_the_left_side_up() -> None:
    leftward = 2.0
    poses = run(CueingParameters(), sustained((0.0, leftward, GRAVITY_M_S2)))
    roll = poses[-1, 3]
    assert roll == pytest.approx(degrees(asin(leftward / GRAVITY_M_S2)), abs=1e-6)
    left_side = rotation_matrix(radians(roll), 0.0, 0.0) @ np.array([0.0, 1.0, 0.0])
    assert left_side[2] > 0
    np.testing.assert_allclose(perceived_specific_force(poses, PERIOD_S)[-1, :2], [0.0, leftward], atol=1e-6)


def test_a_combined_force_is_reproduced_by_the_exact_tilt() -> None:
    force = (1.5, -1.5, GRAVITY_M_S2)
    poses = run(CueingParameters(), sustained(force))
    np.testing.assert_allclose(perceived_specific_force(poses, PERIOD_S)[-1, :2], force[:2], atol=1e-6)


def test_the_tilt_stops_at_its_limit_and_gets_there_at_its_rate_limit() -> None:
    tilt = TiltCoordination(rate_limit_deg_s=3.0, limit_deg=10.0)
    poses = run(CueingParameters(tilt=tilt), sustained((6.0, 0.0, GRAVITY_M_S2), seconds=10.0))
    assert poses[:, 4].min() == pytest.approx(-10.0)
    reached = np.argmax(poses[:, 4] <= -10.0 + 1e-9) * PERIOD_S
    assert reached == pytest.approx(1.0 + 10.0 / 3.0, abs=0.05)  # the step at 1 s, then 3°/s all the way


@settings(max_examples=60, deadline=None)
@given(forces=st.lists(st.tuples(st.floats(-40, 40), st.floats(-40, 40)), min_size=1, max_size=150),
       rate_limit=st.floats(0.1, 30.0), limit=st.floats(0.5, 60.0), period=st.floats(0.001, 0.05),
       break_rad_s=st.floats(0.5, 50.0))
def test_the_tilt_never_turns_faster_than_its_rate_limit_nor_beyond_its_limit(
        forces, rate_limit: float, limit: float, period: float, break_rad_s: float) -> None:
    tilt = TiltCoordination(rate_limit_deg_s=rate_limit, limit_deg=limit, break_rad_s=break_rad_s)
    poses = run(CueingParameters(tilt=tilt), [(fx, fy, GRAVITY_M_S2) for fx, fy in forces], period_s=period)
    tilts = np.vstack([[0.0, 0.0], poses[:, 3:5]])  # no angular rate: roll and pitch are the tilt's
    turns = np.hypot(*np.diff(tilts, axis=0).T)
    assert np.all(turns <= rate_limit * period * (1 + 1e-9))
    assert np.all(np.hypot(*tilts.T) <= limit * (1 + 1e-9))


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["roll", "pitch", "yaw"])
def test_a_sustained_angular_rate_turns_the_platform_then_returns_it_to_zero_angle(axis: int) -> None:
    rates = np.zeros((round(60.0 / PERIOD_S), 3))
    rates[100:, axis] = 0.2  # rad/s from 1 s on: a steady turn
    poses = run(CueingParameters(), sustained(), rates)
    angle = poses[:, 3 + axis]
    assert angle.max() > 1.0  # deg, with the rate's sign: the onset of the turn
    assert abs(angle[-1]) < 0.01  # deg, back while the rate lasts
    assert np.all(poses[:, :3] == 0.0)


def test_the_discrete_channels_follow_the_continuous_filters() -> None:
    parameters = CueingParameters()
    translational = parameters.translational
    forces = sustained((2.0, 0.0, GRAVITY_M_S2), seconds=30.0)
    poses = run(CueingParameters(tilt=NO_TILT.tilt), forces)
    damping, natural, washout = translational.damping[0], translational.break_rad_s[0], translational.washout_rad_s[0]
    continuous = signal.lti([translational.gain[0], 0.0],
                            np.polymul([1.0, 2 * damping * natural, natural**2], [1.0, washout]))
    times = np.arange(len(forces)) * PERIOD_S
    _, expected_m, _ = signal.lsim(continuous, forces[:, 0], times)
    np.testing.assert_allclose(poses[:, 0], expected_m * 1000.0, atol=0.01 * np.abs(expected_m).max() * 1000.0)


def test_streaming_and_batch_agree_and_reset_starts_over(vehicles) -> None:
    vehicle = vehicles["lane_change"]
    parameters = CueingParameters()
    batch = wash_out(parameters, vehicle)
    washout = WashoutFilter(parameters, vehicle.period_s)
    for _ in range(2):
        streamed = np.array([washout.step(f, w) for f, w in zip(vehicle.specific_force, vehicle.angular_rate)])
        np.testing.assert_array_equal(streamed, batch.poses())
        washout.reset()
    assert np.any(batch.onset[:, 1] != 0) and np.any(batch.tilt[:, 3] != 0)
    assert np.all(batch.tilt[:, [0, 1, 2, 5]] == 0)
    np.testing.assert_allclose(batch.poses(0.5), batch.tilt + 0.5 * batch.onset)


def test_the_perceived_specific_force_of_rest_tilt_and_acceleration() -> None:
    n = 50
    rest = perceived_specific_force(np.zeros((n, 6)), PERIOD_S)
    np.testing.assert_array_equal(rest, np.tile([0.0, 0.0, GRAVITY_M_S2], (n, 1)))

    pitch = -10.0
    tilted = perceived_specific_force(np.tile([0, 0, 0, 0, pitch, 0], (n, 1)), PERIOD_S)
    theta = radians(pitch)
    np.testing.assert_allclose(tilted, np.tile([-GRAVITY_M_S2 * sin(theta), 0, GRAVITY_M_S2 * cos(theta)], (n, 1)))

    acceleration = 1.5  # m/s² along x
    times = np.arange(n) * PERIOD_S
    poses = np.zeros((n, 6))
    poses[:, 0] = 0.5 * acceleration * times**2 * 1000.0
    np.testing.assert_allclose(perceived_specific_force(poses, PERIOD_S), np.tile([acceleration, 0, GRAVITY_M_S2], (n, 1)),
                               atol=1e-9)


def test_the_rms_difference_is_over_the_samples_of_the_vector_difference() -> None:
    vehicle = np.array([[3.0, 4.0, 9.81], [0.0, 0.0, 9.81]])
    platform = np.array([[0.0, 0.0, 9.81], [0.0, 0.0, 9.81]])
    assert rms_difference(vehicle, platform) == pytest.approx(np.sqrt((25.0 + 0.0) / 2))


@pytest.mark.parametrize(("period_s", "force", "rate", "problem"), [
    (0.01, np.zeros((3, 3)), np.zeros((4, 3)), "must both be"),
    (0.01, np.zeros((0, 3)), np.zeros((0, 3)), "must both be"),
    (0.01, np.full((3, 3), np.nan), np.zeros((3, 3)), "finite"),
    (0.0, np.zeros((3, 3)), np.zeros((3, 3)), "positive"),
])
def test_a_vehicle_trajectory_refuses_what_is_not_one(period_s, force, rate, problem: str) -> None:
    with pytest.raises(ValueError, match=problem):
        VehicleTrajectory(period_s=period_s, specific_force=force, angular_rate=rate)


def test_the_filter_refuses_a_period_that_is_not_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        WashoutFilter(CueingParameters(), 0.0)


def test_a_channel_at_gain_zero_is_off() -> None:
    off = CueingParameters(translational=TranslationalChannel(gain=(0.0, 0.0, 0.0)),
                           rotational=RotationalChannel(gain=(0.0, 0.0, 0.0)), tilt=TiltCoordination(gain=(0.0, 0.0)))
    poses = run(off, sustained((3.0, -2.0, 12.0)), np.full((6000, 3), 0.3))
    assert np.all(poses == 0.0)
