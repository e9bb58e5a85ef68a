"""The workspace-aware gain and the limiter, on the nominal geometry's own reachability."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.cueing.parameters import CueingParameters, WorkspaceUse
from hexactl.cueing.washout import WashoutChannels, wash_out
from hexactl.cueing.workspace_gain import (
    GAIN_RESOLUTION,
    WorkspaceError,
    gain_to_fill_workspace,
    limit_to_workspace,
    ray_reach,
    reachable,
    soft_saturation,
    stroke_use,
)
from hexactl.kinematics.workspace import assess_pose

WORKSPACE = WorkspaceUse()


def channels(onset: np.ndarray, tilt: np.ndarray | None = None) -> WashoutChannels:
    onset = np.asarray(onset, dtype=float).reshape(-1, 6)
    return WashoutChannels(onset=onset, tilt=np.zeros_like(onset) if tilt is None else np.asarray(tilt, dtype=float))


def test_a_rays_reach_is_reachable_and_the_least_step_beyond_is_not(nominal) -> None:
    directions = np.array([[1, 0, 0, 0, 0, 0], [0, 0, -1, 0, 0, 0], [300, 0, 200, 0, 10, 0], [300, 300, -100, 5, 5, 20]],
                          dtype=float)
    reach = ray_reach(nominal, directions)
    np.testing.assert_allclose(reach[:2], [610.0, 255.0])  # the pose envelope's bounds
    assert reachable(nominal, directions * reach[:, None]).all()
    assert not reachable(nominal, directions * reach[:, None] * (1 + 1e-4)).any()
    assert ray_reach(nominal, np.zeros((1, 6)))[0] == np.inf


def test_the_gain_fills_the_workspace_to_the_use_fraction_along_a_straight_onset(nominal) -> None:
    onset = np.zeros((50, 6))
    onset[:, 0] = np.linspace(0.0, 1000.0, 50)  # mm of x, beyond the 610 mm envelope
    gain = gain_to_fill_workspace(nominal, channels(onset), WORKSPACE)
    resolution = GAIN_RESOLUTION
    assert gain * 1000.0 == pytest.approx(WORKSPACE.use_fraction * 610.0, abs=resolution * 1000.0)
    assert gain * 1000.0 <= WORKSPACE.use_fraction * 610.0


def test_the_gain_stops_at_its_largest_and_at_zero(nominal) -> None:
    small = np.zeros((10, 6))
    small[:, 1] = 10.0
    assert gain_to_fill_workspace(nominal, channels(small), WORKSPACE) == WORKSPACE.max_gain
    tilt = np.zeros((10, 6))
    tilt[5, 4] = -30.0  # beyond the 24° pitch envelope: the tilt alone does not fit
    assert gain_to_fill_workspace(nominal, channels(small, tilt), WORKSPACE) == 0.0


def test_the_gain_on_a_shipped_manoeuvre_keeps_every_pose_within_the_use_fraction_and_no_more(nominal, vehicles) -> None:
    washed = wash_out(CueingParameters(), vehicles["lane_change"])
    gain = gain_to_fill_workspace(nominal, washed, WORKSPACE)
    assert 0 < gain < WORKSPACE.max_gain
    assert reachable(nominal, washed.poses(gain) / WORKSPACE.use_fraction).all()
    step = 2 * GAIN_RESOLUTION
    assert not reachable(nominal, washed.poses(gain + step) / WORKSPACE.use_fraction).all()


def test_a_large_max_gain_finds_the_same_gain(nominal, vehicles) -> None:
    """The bisection halved [0, max_gain] 12 times: with max_gain 100 the gain came out 2 %
    low, with 1e4 (meant as "no cap") 0, the onset channels off without a word."""
    washed = wash_out(CueingParameters(), vehicles["lane_change"])
    usual = gain_to_fill_workspace(nominal, washed, WORKSPACE)
    uncapped = gain_to_fill_workspace(nominal, washed, WorkspaceUse(max_gain=100.0))
    assert uncapped == pytest.approx(usual, abs=2 * GAIN_RESOLUTION)


@settings(max_examples=200, deadline=None)
@given(uses=st.lists(st.floats(0.0, 1e6), min_size=2, max_size=20), knee=st.floats(0.05, 0.9),
       band=st.floats(0.01, 0.09))
def test_the_soft_saturation_is_the_identity_to_the_knee_then_rises_to_the_ceiling_without_reaching_it(
        uses, knee: float, band: float) -> None:
    ceiling = knee + band
    uses = np.sort(np.array(uses))
    saturated = soft_saturation(uses, knee, ceiling)
    below = uses <= knee
    np.testing.assert_array_equal(saturated[below], uses[below])
    assert np.all(saturated <= np.minimum(uses, ceiling))
    assert np.all(np.diff(saturated) >= 0)
    assert np.all(np.diff(saturated) <= np.diff(uses) * (1 + 1e-9) + 1e-12)  # slope at most 1: no faster than the input


ENVELOPE = np.array([610.0, 610.0, 255.0, 24.0, 24.0, 61.0])


@st.composite
def smooth_trajectories(draw) -> np.ndarray:
    """40 samples of three sines per axis with amplitudes up to twice the pose envelope."""
    amplitudes = np.array(draw(st.lists(st.floats(-2.0, 2.0), min_size=18, max_size=18))).reshape(3, 6)
    frequencies = np.array(draw(st.lists(st.floats(0.05, 1.0), min_size=3, max_size=3)))
    phases = np.array(draw(st.lists(st.floats(0.0, 2 * np.pi), min_size=18, max_size=18))).reshape(3, 6)
    times = np.linspace(0.0, 2.0, 40)[:, None]
    return sum(amplitudes[k] * ENVELOPE * np.sin(2 * np.pi * frequencies[k] * times + phases[k]) for k in range(3))


@settings(max_examples=25, deadline=None)
@given(poses=smooth_trajectories())
def test_the_limiter_output_is_always_reachable_continuous_and_leaves_poses_within_the_knee_alone(nominal, poses) -> None:
    limited = limit_to_workspace(nominal, poses, WORKSPACE)
    assert reachable(nominal, limited).all()
    within_knee = reachable(nominal, poses / WORKSPACE.limiter_knee)
    np.testing.assert_array_equal(limited[within_knee], poses[within_knee])
    steps_in = np.linalg.norm(np.diff(poses / ENVELOPE, axis=0), axis=1)
    steps_out = np.linalg.norm(np.diff(limited / ENVELOPE, axis=0), axis=1)
    assert np.all(steps_out <= 2.0 * steps_in + 1e-6)  # no jump: a step out is bounded by the step in


def test_the_limiter_pulls_a_pose_toward_the_zero_posture_along_the_line_to_it(nominal) -> None:
    far = np.array([[1500.0, -300.0, 100.0, 10.0, -40.0, 20.0]])
    limited = limit_to_workspace(nominal, far, WORKSPACE)[0]
    scale = limited / far[0]
    np.testing.assert_allclose(scale, scale[0])
    use = 1.0 / ray_reach(nominal, limited[None])[0]
    assert WORKSPACE.limiter_knee < use <= WORKSPACE.limiter_ceiling


def test_a_limited_pose_that_is_not_reachable_is_an_error_not_a_pose(nominal) -> None:
    # A conditioning limit that refuses every pose, the zero posture too: nothing to pull toward.
    nowhere = nominal.model_copy(update={"limits": nominal.limits.model_copy(update={"max_jacobian_condition": 1.0001})})
    with pytest.raises(WorkspaceError, match="not reachable"):
        limit_to_workspace(nowhere, np.array([[100.0, 0.0, 0.0, 0.0, 0.0, 0.0]]), WORKSPACE)


def test_stroke_use_is_the_fraction_of_the_stroke_from_the_zero_posture_toward_the_end_moved_to(nominal) -> None:
    low, high = nominal.limits.stroke
    neutral = assess_pose(nominal, [0.0] * 6).sensor_mm[0]
    assert stroke_use(nominal, np.zeros((1, 6)))[0] == pytest.approx(0.0, abs=1e-9)
    for z, room in ((-200.0, neutral - low), (200.0, high - neutral)):
        reading = assess_pose(nominal, [0.0, 0.0, z, 0.0, 0.0, 0.0]).sensor_mm[0]
        assert stroke_use(nominal, np.array([[0.0, 0.0, z, 0.0, 0.0, 0.0]]))[0] == pytest.approx(
            abs(reading - neutral) / room, rel=1e-6)
    assert stroke_use(nominal, np.array([[0.0, 0.0, -600.0, 0.0, 0.0, 0.0]]))[0] > 1.0  # below the stroke
