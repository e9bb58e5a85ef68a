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


def test_a_wave_a_stream_and_a_leg_lock_wait_for_the_ramp(rig, calibrated):
    # Each is planned on the active geometry's set-points, which the ramp is still changing.
    from hexactl.control.waves import WaveSpec

    rig.enabled()
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    assert rig.controller.snapshot.ramp_active
    for refused in (rig.controller.wave(WaveSpec(frequency_hz=1.0, cycles=2, axes={"z": {"amplitude": 1.0}})),
                    rig.controller.stream_open("ramp"), rig.controller.leg_lock(1)):
        assert (refused.error, refused.message) == ("busy", "a calibration change is still ramping in")


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
    refused = rig.controller.rollback_calibration()
    assert refused.message == ("there is no earlier calibration to roll back to: none is kept before nominal "
                               "(rollbacks return through the last 16 in force since start-up)")
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    rolled = rig.controller.rollback_calibration()
    assert rolled.ok and rolled.message == "rolled back from calibration cal-1 to nominal"
    assert rolled.details["calibration_id"] == "nominal" and rolled.details["rolled_back_from"] == "cal-1"
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    rig.run(2)
    assert rig.controller.telemetry().calibration_id == "nominal"
    assert rig.controller.status().details["previous_calibration_id"] is None  # an undo, not a toggle
    assert rig.controller.rollback_calibration().error == "no_previous_calibration"
    assert rig.sent[-1] == pytest.approx(original, abs=1e-9)
    rig.assert_setpoints_safe()


def test_loading_the_active_calibration_again_changes_nothing(rig, calibrated):
    rig.enabled()
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    again = rig.controller.load_calibration(calibrated, "cal-1")
    assert again.ok and again.message == "calibration cal-1 is already active: nothing changed"
    assert again.details["change_mm"] == 0.0
    rig.run(2)
    rolled = rig.controller.rollback_calibration()  # back to what came before, not to cal-1 again
    assert rolled.ok and rolled.message == "rolled back from calibration cal-1 to nominal"


def test_rollbacks_walk_back_through_every_load_in_order(rig, geometry):
    from hexactl.control.core import KEPT_CALIBRATIONS

    loads = KEPT_CALIBRATIONS + 2
    for n in range(1, loads + 1):
        assert rig.controller.load_calibration(_with_zero_offset(geometry, 0.1 * n), f"cal-{n}").ok
        rig.run(2)
    assert rig.controller.telemetry().calibration_id == f"cal-{loads}"
    walked = []
    while (result := rig.controller.rollback_calibration()).ok:
        rig.run(2)
        walked.append(rig.controller.telemetry().calibration_id)
    # The most recent KEPT_CALIBRATIONS, newest first; the oldest ones (nominal, cal-1) forgotten.
    assert walked == [f"cal-{n}" for n in range(loads - 1, loads - 1 - KEPT_CALIBRATIONS, -1)]
    assert result.error == "no_previous_calibration"
    # The nominal geometry is in no history now (as after a restart on a kept calibration): how to get back to it.
    assert result.message.endswith("; to go back to the nominal geometry, load its file (hexactl load-calibration "
                                   "FILE: the service's --config)"), result.message


def test_a_rollback_overtaken_by_a_load_is_refused_as_stale(rig, calibrated, geometry):
    """Two clients: one rolls back while another's load is still queued before it."""
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    loaded = rig.controller.load_calibration(_with_zero_offset(geometry, 0.5), "cal-2")
    rolled = rig.controller.rollback_calibration()  # checked against cal-1's history
    rig.run(2)
    assert rig.controller.outcome(loaded.details["ticket"]).ok
    assert rig.controller.outcome(rolled.details["ticket"]).error == "stale_plan"
    assert rig.controller.telemetry().calibration_id == "cal-2"


def _with_zero_offset(geometry: Geometry, offset_mm: float) -> Geometry:
    """Zero lengths ``offset_mm`` longer: every sensor set-point ``offset_mm`` lower."""
    return _variant(geometry, zero_lengths=[z + offset_mm for z in geometry.zero_lengths])


def _accepting_large_changes(make_rig, geometry):
    """A rig (and its nominal geometry) that accepts zero lengths hundreds of mm from the
    nominal ones, so that the checks after plausibility can be seen at work."""
    from hexactl.control.config import ControllerConfig

    tolerant = _variant(geometry, limits={"calibration_zero_length_tolerance_mm": 300.0})
    return make_rig(config=ControllerConfig(calibration_max_change_mm=400.0), geometry=tolerant), tolerant


def test_a_calibration_that_puts_the_current_pose_out_of_reach_is_refused(make_rig, geometry):
    rig, geometry = _accepting_large_changes(make_rig, geometry)
    rig.enabled()
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
    from hexactl.control.local_controller import LocalController
    from hexactl.sim.ideal_actuators import IdealActuators

    wide = _variant(geometry, limits={"stroke": (-100.0, 950.0)})
    with pytest.raises(ValueError, match=r"stroke: \(-100.0, 950.0\) \(hardware: \(0.0, 850.0\)\)"):
        LocalController.in_thread(IdealActuators([400.0] * 6), wide, "wide", nominal=geometry)


def test_a_calibration_that_would_move_a_leg_far_is_refused(rig, geometry):
    rig.enabled()
    shifted = _variant(geometry, zero_lengths=[z - 30.0 for z in geometry.zero_lengths])
    result = rig.controller.load_calibration(shifted, "shifted")
    assert not result.ok and result.error == "calibration_change_too_large"
    assert result.details["change_mm"] == pytest.approx(30.0)
    # Found from outside: the refusal said no way out (a rollback to the nominal one was
    # refused the same way). What it says to do works: disabled, the swap ramps nothing.
    assert "stop and disable first" in result.message
    assert rig.controller.disable().ok
    rig.run(2)
    assert rig.controller.load_calibration(shifted, "shifted").ok


def test_the_remaining_sequence_is_checked_against_the_new_calibration(make_rig, geometry):
    from hexactl.control.sequences import MotionSequence, SequenceWaypoint

    rig, geometry = _accepting_large_changes(make_rig, geometry)
    rig.enabled()
    out_and_back = MotionSequence(name="out", waypoint=[SequenceWaypoint(pose=[0, 0, 10, 0, 0, 0], dwell=1.0),
                                                        SequenceWaypoint(pose=[0, 0, 0, 0, 0, 60])])
    assert rig.controller.play(out_and_back).ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")  # at z = 10 mm
    # 100 mm shorter legs: fine here and along the ramp, but yaw = 60° needs readings up to 872 mm (beyond 850).
    result = rig.controller.load_calibration(_with_zero_offset(geometry, -100.0), "short legs")
    assert not result.ok and result.error == "invalid_geometry", result.message
    assert {v["kind"] for v in result.details["violations"]} == {"stroke_high"}
    assert "ramp_fraction" not in result.details


def test_a_change_is_checked_along_its_ramp(make_rig, geometry):
    rig, geometry = _accepting_large_changes(make_rig, geometry)
    rig.enabled()
    assert rig.controller.move([600, 0, 0, 0, 0, 0]).ok
    rig.settle()
    # 250 mm shorter legs: the platform would pass through poses outside the envelope while ramping.
    result = rig.controller.load_calibration(_with_zero_offset(geometry, -250.0), "short legs")
    assert not result.ok and result.error == "invalid_geometry"
    assert "ramp fraction" in result.message and 0 < result.details["ramp_fraction"] <= 1
    assert {v["kind"] for v in result.details["violations"]} <= {"pose_range", "base_cone", "platform_cone",
                                                                   "near_singular"}


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


@pytest.mark.parametrize("case", ["base joints +1 m", "platform joints +300 mm", "home moved"])
@pytest.mark.parametrize("enabled", [True, False])
def test_an_implausible_calibration_compensated_at_the_current_pose_is_refused(make_rig, geometry, case, enabled):
    from tests.kinematics.calibrations import implausible_calibrations

    pose = [100.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    rig = make_rig(start_pose=pose)
    if enabled:
        rig.enabled()
    rig.run(3)
    calibration, parameter = implausible_calibrations(geometry, pose)[case]
    result = rig.controller.load_calibration(calibration, "implausible")
    assert not result.ok and result.error == "invalid_geometry"
    assert parameter in result.message and "[limits] calibration_" in result.message
    assert any(problem.startswith(parameter) for problem in result.details["implausible"])
    rig.run(2)
    assert rig.controller.telemetry().calibration_id == "nominal"


def test_a_start_calibration_must_be_plausible(geometry):
    from hexactl.control.local_controller import LocalController
    from hexactl.sim.ideal_actuators import IdealActuators
    from tests.kinematics.calibrations import implausible_calibrations

    calibration, _ = implausible_calibrations(geometry, [0.0] * 6)["platform joints +300 mm"]
    with pytest.raises(ValueError, match=r"platform_joints\[0\] \(leg 1\) is 300.0 mm from the nominal"):
        LocalController.in_thread(IdealActuators([400.0] * 6), calibration, "bad", nominal=geometry)


def test_a_move_to_the_envelopes_bound_is_accepted(rig):
    rig.enabled()
    assert rig.controller.validate_pose([610, 0, 0, 0, 0, 0]).ok
    assert rig.controller.move([-610, 0, 0, 0, 0, 0]).ok
    rig.settle()
    assert rig.controller.telemetry().pose_command[0] == -610.0


def test_swaps_and_rollbacks_many_times_a_second_during_moves_never_clamp(rig, geometry):
    """Issue 10: 50 swaps a second with rollbacks clamped the set-points now and then.
    Here a swap or rollback every 10 cycles (50 a second at 500 Hz) while the platform
    moves between far poses, on plausible calibrations (true platforms with the
    simulator's manufacturing errors)."""
    import random

    from hexactl.sim.true_platform import true_geometry

    calibrations = [true_geometry(geometry, seed) for seed in range(6)]
    rng = random.Random(3)
    rig.enabled()
    accepted = 0
    for goal in ([300, 300, 150, 10, -10, 30], [-300, -200, -150, -10, 10, -30], [0, 0, 0, 0, 0, 0]):
        assert rig.controller.move(goal).ok
        while True:
            if rig.controller.snapshot.previous is not None and rng.random() < 0.5:
                result = rig.controller.rollback_calibration()
            else:
                result = rig.controller.load_calibration(rng.choice(calibrations), f"cal-{rng.random()}")
            accepted += result.ok
            rig.run(10)
            if rig.controller.snapshot.motion.value == "holding":
                break
    assert accepted > 100
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_validate_calibration_says_the_change_a_load_would_make_and_swaps_nothing(rig, calibrated):
    rig.enabled()
    rig.run(3)
    before = rig.sent[-1].copy()
    checked = rig.controller.validate_calibration(calibrated, "cal-1", "cal-1.toml")
    assert checked.ok and checked.details["calibration_id"] == "cal-1"
    rig.run(5)
    assert rig.controller.telemetry().calibration_id != "cal-1" and not rig.controller.snapshot.ramp_active
    assert rig.sent[-1] == pytest.approx(before, abs=1e-12)
    loaded = rig.controller.load_calibration(calibrated, "cal-1", "cal-1.toml")
    assert loaded.ok and loaded.details["change_mm"] == checked.details["change_mm"]


def test_validate_calibration_refuses_what_a_load_would_refuse(rig, geometry):
    rig.enabled()
    other_limits = _variant(geometry, limits={"leg_velocity_mm_s": geometry.limits.leg_velocity_mm_s * 2})
    checked = rig.controller.validate_calibration(other_limits, "cal-2")
    loaded = rig.controller.load_calibration(other_limits, "cal-2")
    assert not checked.ok and (checked.error, checked.message) == (loaded.error, loaded.message)


@pytest.mark.parametrize("latch", ["estop", "disable"])
def test_a_swap_while_not_enabled_says_that_nothing_ramps_and_changes_no_setpoint(rig, calibrated, latch):
    # Found from outside: after an E-stop, `hexactl rollback-calibration` answered "set-points
    # change by up to 3.000 mm" though the loop held them where they were; a 30 mm load was
    # refused "too far to ramp in while enabled: ... stop and disable first", which an E-stop
    # cannot do. Only an enabled controller ramps; otherwise the reply says what happens.
    rig.enabled()
    assert rig.controller.load_calibration(calibrated, "cal-1").ok
    rig.run(2)
    rig.run_until(lambda: not rig.controller.snapshot.ramp_active)
    assert getattr(rig.controller, latch)().ok
    rig.run(2)
    held, sent = rig.controller.snapshot.setpoints, len(rig.sent)
    for checked in (rig.controller.validate_calibration(rig.geometry, "nominal"), rig.controller.rollback_calibration()):
        assert checked.ok and checked.details["change_mm"] == 0.0, checked.message
        state = rig.controller.snapshot.state.value
        assert f"nothing is ramped: the controller is {state}" in checked.message
        assert "legs up to 4.000 mm from where the active one does" in checked.message  # for people
    rig.run(3)
    assert rig.controller.telemetry().calibration_id == "nominal"
    assert rig.controller.snapshot.setpoints == held and len(rig.sent) == sent  # none sent, none changed
    shifted = _variant(calibrated, zero_lengths=[z - 30.0 for z in calibrated.zero_lengths])
    assert rig.controller.load_calibration(shifted, "shifted").ok
    rig.run(2)
    if latch == "estop":
        assert rig.controller.reset().ok
        rig.run_until(lambda: all(a.state.name == "DISABLED" for a in rig.controller.snapshot.feedback.actuators))
    rig.enabled()
    rig.run(50)
    assert rig.controller.telemetry().calibration_id == "shifted" and not rig.controller.snapshot.ramp_active
    rig.assert_setpoints_safe()  # enabled where the legs are: no step


def test_a_swap_checks_a_work_frame_sequence_at_the_platform_poses_it_will_take(make_rig, geometry):
    # Found from outside: with a tool 300 mm above the platform, a calibration loaded while a
    # work-frame sequence dwelt was refused "z 300 mm outside the pose envelope": the rest
    # of the sequence (the tool's poses in the work frame) was checked as platform poses.
    from hexactl.control.frames import OperatorFrames
    from hexactl.control.sequences import sequence_from_mapping

    rig, geometry = _accepting_large_changes(make_rig, geometry)
    assert rig.controller.set_frames(OperatorFrames(tool=(0, 0, 300, 0, 0, 0))).ok
    rig.enabled()
    pivot = sequence_from_mapping({"name": "pivot", "frame": "work", "waypoint": [
        {"pose": [0, 0, 310, 0, 0, 0], "dwell": 1.0}, {"pose": [0, 0, 300, 0, 0, 60]}]})
    assert rig.controller.play(pivot).ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")  # at z = 10 mm
    # 100 mm shorter legs: fine here and along the ramp, but yaw = 60° needs readings up to 872 mm (beyond 850).
    refused = rig.controller.load_calibration(_with_zero_offset(geometry, -100.0), "short legs")
    assert not refused.ok and refused.error == "invalid_geometry", refused.message
    assert {v["kind"] for v in refused.details["violations"]} == {"stroke_high"}
    small = _with_zero_offset(geometry, 2.0)
    assert (loaded := rig.controller.load_calibration(small, "small")).ok, loaded.message
    rig.settle()
    rig.assert_setpoints_safe()


def test_a_load_a_preview_and_a_rollback_answer_with_the_identification_warnings_of_the_calibration(rig, calibrated):
    """Found from outside: a calibration written "weakly determined" (a combination known to
    ±70 mm) was loaded with no word of it; its file now keeps the warnings, and every swap
    to it repeats them."""
    warned = ("weakly determined: … the worst combination 0.66·B4.z −0.66·zero4 is known to ±70.6 mm",
              "residuals are 0.55× the noise model")
    table = {"method": "full", "created": "now", "input_sha256": "0" * 64, "postures": 8, "residual_rms_mm": 0.1,
             "status": "weakly determined", "warnings": warned}
    weak = _variant(calibrated, calibration=table)
    assert rig.controller.validate_calibration(weak, "weak").details["warnings"] == list(warned)
    loaded = rig.controller.load_calibration(weak, "weak")
    assert loaded.ok and loaded.details["warnings"] == list(warned)
    rig.run(2)
    assert rig.controller.load_calibration(weak, "weak").details["warnings"] == list(warned)  # already active
    plain = rig.controller.load_calibration(_variant(calibrated, zero_lengths=[z + 0.1 for z in calibrated.zero_lengths]),
                                            "plain")
    assert plain.ok and plain.details["warnings"] == []  # a geometry with no [calibration] table
    rig.run(2)
    back = rig.controller.rollback_calibration()
    assert back.ok and back.details["calibration_id"] == "weak" and back.details["warnings"] == list(warned)
