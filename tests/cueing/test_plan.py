"""The cue plan ``hexactl cue`` streams: every pose reachable, smooth, and the
workspace-aware gain's effect on the cue's fidelity on the shipped manoeuvres."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.application.cueing import CuePlan, plan_cue
from hexactl.cueing.parameters import CueingParameters
from hexactl.cueing.washout import perceived_specific_force, rms_difference, wash_out
from hexactl.cueing.workspace_gain import reachable
from hexactl.kinematics.axes import RelativeMmDeg

MANOEUVRES = ("braking", "lane_change")


@pytest.fixture(scope="module")
def plans(nominal, vehicles) -> dict[tuple[str, bool], CuePlan]:
    """Each shipped manoeuvre's plan with and without the workspace-aware gain."""
    return {(name, gain): plan_cue(vehicles[name], CueingParameters(), nominal, workspace_gain=gain)
            for name in MANOEUVRES for gain in (True, False)}


@pytest.mark.parametrize("gain", [True, False], ids=["gain", "no-gain"])
@pytest.mark.parametrize("name", MANOEUVRES)
def test_every_planned_pose_is_reachable(plans, nominal, name: str, gain: bool) -> None:
    plan = plans[name, gain]
    assert reachable(nominal, np.array(plan.poses)).all()


@pytest.mark.parametrize("gain", [True, False], ids=["gain", "no-gain"])
@pytest.mark.parametrize("name", MANOEUVRES)
def test_a_plan_is_one_pose_per_sample_with_the_force_they_make_felt(plans, vehicles, name: str, gain: bool) -> None:
    plan, vehicle = plans[name, gain], vehicles[name]
    assert plan.period_s == vehicle.period_s and len(plan.poses) == len(vehicle)
    assert all(type(pose) is RelativeMmDeg for pose in plan.poses)
    np.testing.assert_array_equal(plan.vehicle_specific_force, vehicle.specific_force)
    felt = perceived_specific_force(np.array(plan.poses), plan.period_s)
    np.testing.assert_array_equal(plan.platform_specific_force, felt)
    assert plan.rms_error == rms_difference(vehicle.specific_force, plan.platform_specific_force)
    if not gain:
        assert plan.gain == 1.0


@pytest.mark.parametrize("name", MANOEUVRES)
def test_a_plan_starts_at_the_zero_posture_and_never_jumps(plans, name: str) -> None:
    for gain in (True, False):
        poses = np.array(plans[name, gain].poses)
        np.testing.assert_allclose(poses[0], 0.0, atol=1e-6)
        steps = np.abs(np.diff(poses, axis=0)).max(axis=0)
        assert np.all(steps[:3] < 15.0) and np.all(steps[3:] < 0.5)  # mm, deg per 10 ms: 1.5 m/s, 50 deg/s at most


def test_the_gain_shrinks_a_cue_that_does_not_fit_and_grows_one_that_does(plans, nominal, vehicles) -> None:
    braking, lane_change = plans["braking", True], plans["lane_change", True]
    assert 0 < braking.gain < 1 < lane_change.gain
    raw = wash_out(CueingParameters(), vehicles["braking"]).poses()
    assert not reachable(nominal, raw).all()  # without the gain the limiter has to squash it


@pytest.mark.parametrize("name", MANOEUVRES)
def test_the_workspace_gain_lowers_the_rms_error_on_the_shipped_manoeuvres(plans, name: str) -> None:
    assert plans[name, True].rms_error < plans[name, False].rms_error
