"""Live calibration swap: validated, swapped at a cycle boundary, ramped, rolled back."""

import numpy as np
import pytest

from hexactl.kinematics.geometry import Geometry


def _variant(geometry: Geometry, **changes) -> Geometry:
    data = geometry.model_dump()
    for key, value in changes.items():
        if key == "limits":
            data["limits"] = {**data["limits"], **value}
        else:
            data[key] = value
    return Geometry.model_validate(data)


@pytest.fixture
def calibrated(geometry):
    """A plausible identification result: joints and zero lengths off by millimetres."""
    base = [list(b) for b in geometry.base_joints]
    base[3][0] += 3.0
    base[0][2] -= 2.0
    zero = list(geometry.zero_lengths)
    zero[1] += 4.0
    return _variant(geometry, base_joints=base, zero_lengths=zero)


def test_swap_ramps_the_setpoints_within_the_calibration_share_of_the_velocity(rig, calibrated):
    rig.enabled()
    rig.run(5)
    start = len(rig.sent)
    result = rig.controller.load_calibration(calibrated, "cal-1", "cal-1.toml")
    assert result.ok and result.details["change_mm"] == pytest.approx(4.0, abs=0.5)
    rig.run(2)
    assert rig.controller.telemetry().calibration_id == "cal-1"
    assert rig.controller.snapshot.ramp_active
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    rig.run(5)
    steps = np.abs(np.diff(rig.sent[start - 1:], axis=0))
    fraction = rig.controller.config.calibration_ramp_fraction
    assert steps.max() <= fraction * rig.max_step_mm * (1 + 1e-9)  # never a step
    assert steps.max() > 0.5 * fraction * rig.max_step_mm
    # The same commanded pose, now reached through the new geometry.
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.kinematics.pose import absolute_from_relative

    pose = rig.controller.telemetry().pose_command
    assert pose == pytest.approx((0,) * 6, abs=1e-9)
    assert rig.sent[-1] == pytest.approx(sensor_setpoints(calibrated.legs, absolute_from_relative(calibrated.home, pose)),
                                         abs=1e-9)
    rig.run(100)  # the actuators' lag dies out
    assert rig.controller.telemetry().pose_measured == pytest.approx((0,) * 6, abs=1e-4)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_swap_while_moving_stays_within_the_velocity_limit(rig, calibrated):
    rig.enabled()
    assert rig.controller.move([0, 0, 200, 0, 0, 0]).ok  # legs at near their planned top speed
    rig.run(200)
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.settle()
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0
    assert rig.controller.telemetry().pose_command == pytest.approx((0, 0, 200, 0, 0, 0), abs=1e-9)


def test_rollback_ramps_back_to_the_previous_calibration(rig, calibrated):
    rig.enabled()
    rig.run(3)
    original = rig.sent[-1].copy()
    assert rig.controller.rollback_calibration().error == "no_previous_calibration"
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    assert rig.controller.rollback_calibration().ok
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    rig.run(2)
    assert rig.controller.telemetry().calibration_id == "nominal"
    assert rig.controller.status().details["previous_calibration_id"] == "cal-1"
    assert rig.sent[-1] == pytest.approx(original, abs=1e-9)
    rig.assert_setpoints_safe()


def _with_zero_offset(geometry: Geometry, offset_mm: float) -> Geometry:
    """Zero lengths ``offset_mm`` longer: every sensor set-point ``offset_mm`` lower."""
    return _variant(geometry, zero_lengths=[z + offset_mm for z in geometry.zero_lengths])


def _accepting_large_changes(make_rig):
    from hexactl.control.config import ControllerConfig

    return make_rig(config=ControllerConfig(calibration_max_change_mm=400.0))


def test_a_calibration_that_puts_the_current_pose_out_of_reach_is_refused(make_rig, geometry):
    rig = _accepting_large_changes(make_rig).enabled()
    assert rig.controller.move([0, 0, -240, 0, 0, 0]).ok
    rig.settle()  # the legs read about 134 mm here
    result = rig.controller.load_calibration(_with_zero_offset(geometry, 150.0), "long legs")
    assert not result.ok and result.error == "invalid_geometry"
    assert result.details["violations"][0]["kind"] == "stroke_low"
    rig.run(5)
    assert rig.controller.telemetry().calibration_id == "nominal"


@pytest.mark.parametrize("limits", [
    {"stroke": (-100.0, 950.0)},  # wider: would let set-points leave the actuators' real stroke
    {"stroke": (140.0, 850.0)},  # narrower: limits are the hardware's, not the calibration's
    {"leg_velocity_mm_s": 800.0},
    {"pose_max": (700.0, 610.0, 255.0, 24.0, 24.0, 61.0)},
])
def test_a_calibration_cannot_change_the_hardware_limits(rig, calibrated, limits):
    rig.enabled()
    changed = _variant(calibrated, limits=limits)
    result = rig.controller.load_calibration(changed, "changed")
    assert not result.ok and result.error == "invalid_geometry"
    assert "[limits] differ from the hardware's" in result.message
    assert [difference.split(":")[0] for difference in result.details["differences"]] == list(limits)
    assert rig.controller.load_calibration(calibrated, "calibrated").ok  # same limits: accepted


def test_a_controller_refuses_a_start_geometry_with_other_limits(geometry):
    from hexactl.control.controller import Controller
    from hexactl.sim.ideal_actuators import IdealActuators

    wide = _variant(geometry, limits={"stroke": (-100.0, 950.0)})
    with pytest.raises(ValueError, match=r"stroke: \(-100.0, 950.0\) \(hardware: \(0.0, 850.0\)\)"):
        Controller.in_thread(IdealActuators([400.0] * 6), wide, "wide", hardware_limits=geometry.limits)


def test_a_calibration_that_would_move_a_leg_far_is_refused(rig, geometry):
    rig.enabled()
    shifted = _variant(geometry, zero_lengths=[z - 30.0 for z in geometry.zero_lengths])
    result = rig.controller.load_calibration(shifted, "shifted")
    assert not result.ok and result.error == "calibration_change_too_large"
    assert result.details["change_mm"] == pytest.approx(30.0)


def test_the_remaining_sequence_is_checked_against_the_new_calibration(make_rig, geometry):
    rig = _accepting_large_changes(make_rig).enabled()
    assert rig.controller.play("x_sweep").ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")  # at x = 600 mm
    # 250 mm shorter legs: x = 600 needs readings up to 797 mm (fine), x = -600 up to 870 (beyond 850).
    result = rig.controller.load_calibration(_with_zero_offset(geometry, -250.0), "short legs")
    assert not result.ok and result.error == "invalid_geometry"
    assert {v["kind"] for v in result.details["violations"]} == {"stroke_high"}


def test_swap_while_disabled_takes_effect_at_once_and_is_refused_while_locked(rig, calibrated):
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run()
    assert rig.controller.telemetry().calibration_id == "cal-1" and not rig.controller.snapshot.ramp_active
    rig.enabled()
    assert rig.controller.leg_lock(2).ok
    rig.run()
    assert rig.controller.rollback_calibration().error == "leg_locked"
    assert rig.controller.load_calibration("not a geometry", "x").error == "invalid_argument"
    assert rig.controller.load_calibration(calibrated, "").error == "invalid_argument"
