"""Start-up, moves, validation and the set-point limits, in simulated time."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

START = (30.0, -20.0, 10.0, 1.0, 2.0, -3.0)


def test_starts_from_the_pose_the_actuators_are_at_without_a_jump(make_rig):
    rig = make_rig(start_pose=START)
    telemetry = rig.controller.telemetry()
    assert telemetry.state == "disabled" and telemetry.pose_measured == pytest.approx(START, abs=1e-6)
    assert telemetry.pose_command == pytest.approx(START, abs=1e-6)
    before = rig.actuators.read_feedback().positions_mm
    rig.enabled()
    rig.run(50)
    assert rig.controller.telemetry().pose_command == pytest.approx(START, abs=1e-6)
    assert np.max(np.abs(rig.sent - before)) < 1e-6  # holds exactly where it was
    assert rig.actuators.read_feedback().positions_mm == pytest.approx(before, abs=1e-6)


def test_restart_starts_from_where_the_platform_was_left(make_rig, geometry):
    from hexactl.control.local_controller import LocalController

    rig = make_rig().enabled()
    assert rig.controller.move([100, 50, 20, 1, 2, 3]).ok
    rig.settle()
    rig.run(100)  # the actuators' lag dies out
    assert rig.controller.disable().ok
    rig.run(2)
    again = LocalController.in_thread(rig.actuators, geometry, "nominal", clock_ns=rig.clock)
    assert again.telemetry().pose_command == pytest.approx((100, 50, 20, 1, 2, 3), abs=1e-6)


def test_move_reaches_the_target_within_the_limits(make_rig):
    rig = make_rig(start_pose=START).enabled()
    result = rig.controller.move([300, 0, 50, 0, 5, 0])
    assert result.ok and result.details["goal"] == pytest.approx([300, 0, 50, 0, 5, 0])
    cycles = rig.settle()
    assert cycles * rig.period_ns / 1e9 == pytest.approx(result.details["duration_s"], abs=0.01)
    rig.run(100)
    telemetry = rig.controller.telemetry()
    assert telemetry.pose_command == pytest.approx((300, 0, 50, 0, 5, 0), abs=1e-9)
    assert telemetry.pose_measured == pytest.approx((300, 0, 50, 0, 5, 0), abs=1e-4)
    assert telemetry.loop.guard_clamps == 0
    rig.assert_setpoints_safe()


def test_a_requested_duration_is_honoured(rig):
    rig.enabled()
    assert rig.controller.move([0, 0, 20, 0, 0, 0], duration=3.0).ok
    cycles = rig.settle()
    assert cycles * rig.period_ns / 1e9 == pytest.approx(3.0, abs=2 * rig.period_ns / 1e9)


@pytest.mark.parametrize("pose", [(0, 0, 10, 0, 0, 0), (100, 50, -30, 2, 3, 4), (0, 0, 0, 0, 0, 5)])
@pytest.mark.parametrize("duration", [2.0, 60.0, 300.0, 600.0])
def test_a_requested_duration_is_a_minimum_even_when_long(rig, pose, duration):
    """Found from outside: 60 s took 59.952 s, 300 s 299.76 s (scaled limits give nearly, not
    exactly, k times the natural duration)."""
    rig.enabled()
    result = rig.controller.validate_pose(pose, duration)
    assert result.ok, result.message
    assert duration - 1e-6 <= result.details["duration_s"] <= duration * 1.001


def test_a_speed_too_low_for_the_trajectory_generator_is_refused_saying_what_to_do(rig):
    rig.enabled()
    refused = rig.controller.validate_pose((0, 0, 10, 0, 0, 0), None, 1e-9)
    assert refused.error == "planning_failed" and "at speed 1e-09 of the velocity limits: raise the speed" in refused.message


def test_a_move_to_where_it_is_with_a_duration_is_taken_and_moves_nothing(rig):
    rig.enabled()
    here = list(rig.controller.telemetry().pose_command)
    assert rig.controller.move(here, duration=2.0).ok  # was internal_error: ZeroDivisionError
    rig.settle()
    assert list(rig.controller.telemetry().pose_command) == pytest.approx(here, abs=1e-9)
    rig.assert_setpoints_safe()


def test_a_fast_request_is_stretched_to_keep_the_legs_under_their_limit(make_rig, geometry):
    from hexactl.control.config import ControllerConfig
    from hexactl.control.trajectory import MotionLimits

    fast = MotionLimits(max_velocity=(2000, 2000, 2000, 100, 100, 100),
                        max_acceleration=(20000, 20000, 20000, 1000, 1000, 1000),
                        max_jerk=(2e5, 2e5, 2e5, 1e4, 1e4, 1e4))
    rig = make_rig(config=ControllerConfig(motion=fast)).enabled()
    assert rig.controller.move([500, 0, 0, 0, 0, 20]).ok
    rig.settle()
    steps = np.abs(np.diff(rig.sent, axis=0)) / (rig.period_ns / 1e9)
    budget = geometry.limits.leg_velocity_mm_s * (1 - rig.controller.config.calibration_ramp_fraction)
    assert steps.max() <= budget * 1.01  # the plan, not the guard, kept it in
    assert steps.max() > 0.8 * budget  # and it did go fast
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_refused_move_leaves_the_platform_where_it_is(make_rig):
    rig = make_rig(start_pose=START).enabled()
    rig.run(10)
    sent_before = len(rig.sent)
    result = rig.controller.move([700, 0, 0, 0, 0, 0])
    assert not result.ok and result.error == "path_violation"
    violation = result.details["violations"][0]
    assert violation["kind"] == "pose_range" and violation["axis"] == "x"
    assert violation["pose"] == [700, 0, 0, 0, 0, 0] or violation["pose"] == (700, 0, 0, 0, 0, 0)
    rig.run(200)
    assert np.max(np.abs(rig.sent[sent_before:] - rig.sent[sent_before - 1])) == 0.0
    assert rig.controller.telemetry().pose_command == pytest.approx(START, abs=1e-6)


def test_a_path_through_a_violation_is_refused_even_if_both_ends_are_valid(rig):
    # Two valid low poses whose straight line takes leg 6 below its stroke: the
    # minimum-length constraint is not convex.
    start, goal = [-353, -370, -240, 1, 3, 23], [-263, -53, -240, 13, -5, -43]
    rig.enabled()
    assert rig.controller.move(start).ok
    rig.settle()
    assert rig.controller.validate_pose(start).ok
    result = rig.controller.move(goal)
    assert not result.ok and result.error == "path_violation"
    violation = result.details["violations"][0]
    assert violation["kind"] == "stroke_low" and violation["leg"] == 6
    assert start[1] < violation["pose"][1] < goal[1]  # where on the way it happens


@pytest.mark.filterwarnings("error")  # numpy's overflow warning would mean a huge pose reached the math
@pytest.mark.parametrize("pose", [[float("nan")] * 6, [0, 0, 0, 0, 0, math.inf], [1, 2, 3], None, "abcdef",
                                  [1e300] * 6, [0, 0, 0, 0, 0, "x"]])
def test_malformed_poses_are_refused_not_raised(rig, pose):
    rig.enabled()
    result = rig.controller.move(pose)
    assert not result.ok and result.error in ("invalid_argument", "path_violation")


def test_a_pose_beyond_any_reach_is_refused_with_its_units_named(rig):
    result = rig.controller.validate_pose([0, 0, 1.5e9, 0, 0, 0])
    assert not result.ok and result.error == "invalid_argument"
    assert "z 1.5e+09" in result.message and "units" in result.message, result.message


@pytest.mark.parametrize(("duration", "speed"), [(-1.0, None), (0.0, None), (math.nan, None), ("3", None),
                                                 (None, 0.0), (None, 1.5), (None, math.inf), (2.0, 0.5), (True, None)])
def test_bad_durations_and_speeds_are_refused(rig, duration, speed):
    rig.enabled()
    result = rig.controller.move([10, 0, 0, 0, 0, 0], duration=duration, speed=speed)
    assert not result.ok and result.error == "invalid_argument"


def test_move_needs_enable(rig):
    result = rig.controller.move([10, 0, 0, 0, 0, 0])
    assert not result.ok and result.error == "not_enabled"
    assert rig.controller.validate_pose([10, 0, 0, 0, 0, 0]).ok  # validation works disabled


def test_a_new_move_while_moving_replans_smoothly(rig):
    rig.enabled()
    assert rig.controller.move([400, 0, 0, 0, 0, 0]).ok
    rig.run(300)
    assert rig.controller.snapshot.motion.value == "moving"
    assert rig.controller.move([0, 300, 0, 0, 0, 0]).ok
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((0, 300, 0, 0, 0, 0), abs=1e-9)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_stop_brakes_smoothly_short_of_the_goal(rig):
    rig.enabled()
    assert rig.controller.move([500, 0, 0, 0, 0, 0]).ok
    rig.run(400)
    stopping = rig.controller.stop()
    assert stopping.ok and stopping.message == "stopping"
    rig.settle()
    x = rig.controller.telemetry().pose_command[0]
    assert 0 < x < 500
    rig.assert_setpoints_safe()


def test_stop_with_nothing_to_stop_says_so_and_is_not_refused(rig):
    """Issue 16: ``stop`` while disabled answered "stopping"."""
    disabled = rig.controller.stop()
    assert disabled.ok and disabled.message == "nothing to stop: the controller is disabled"
    rig.enabled()
    at_rest = rig.controller.stop()
    assert at_rest.ok and at_rest.message == "nothing to stop: the platform is at rest"
    assert rig.controller.estop().ok
    rig.run()
    latched = rig.controller.stop()  # it said "the controller is estop"
    assert latched.ok and latched.message == "nothing to stop: the controller is in ESTOP (reset it to go on)"


def test_a_plan_made_before_the_target_changed_is_refused_as_stale(rig):
    from hexactl.control import commands as cmd
    from hexactl.control.planning import Segment

    rig.enabled()
    epoch = rig.controller.snapshot.epoch
    assert rig.controller.stop().ok  # advances the epoch
    rig.run()
    rig.controller.thread.submit(cmd.Move(999, epoch, Segment((100.0, 0, 0, 0, 0, 0), 1.0, 1.0, 0.0, 1.0)))
    rig.run()
    outcome = rig.controller.outcome(999)
    assert not outcome.ok and outcome.error == "stale_plan"
    assert rig.controller.snapshot.motion.value == "holding"


def test_a_move_the_motion_has_outrun_since_it_was_planned_is_refused_not_faulted(rig):
    """With the loop in its own thread, a move replacing a running one is carried out some
    cycles after the snapshot it was planned from. Here, 0.2 s into a move down by 113 mm,
    a move stretched 4× is valid from the snapshot but not 10 cycles later, when it
    arrives (ruckig refuses it from there). The loop used to take it and latch
    planner_error; it refuses it, and the running move goes on to its goal."""
    from hexactl.control import commands as cmd
    from hexactl.control.planning import Segment
    from hexactl.control.trajectory import preview

    rig.enabled()
    assert rig.controller.move([0, 0, -113, 0, 0, 0]).ok
    rig.run(100)
    planned_from = rig.controller.snapshot
    goal = (0.0, 180.0, -65.0, 0.0, 0.0, math.radians(16))
    period_s = rig.controller.config.loop.period_s
    assert preview(rig.controller.config.motion, period_s, planned_from.trajectory, goal, 4.0) is not None
    rig.run(10)
    assert preview(rig.controller.config.motion, period_s, rig.controller.snapshot.trajectory, goal, 4.0) is None
    rig.controller.thread.submit(cmd.Move(999, planned_from.epoch, Segment(goal, 4.0, 1.0, 0.0, 10.0)))
    rig.run()
    outcome = rig.controller.outcome(999)
    assert not outcome.ok and outcome.error == "stale_plan"
    rig.settle()
    assert rig.controller.snapshot.state.value == "enabled" and rig.controller.snapshot.faults == ()
    assert rig.controller.telemetry().pose_command == pytest.approx((0, 0, -113, 0, 0, 0), abs=1e-9)
    rig.assert_setpoints_safe()


reachable = st.tuples(st.floats(-600, 600), st.floats(-600, 600), st.floats(-250, 250),
                      st.floats(-23, 23), st.floats(-23, 23), st.floats(-60, 60))
wild = st.one_of(st.floats(-2000, 2000), st.sampled_from([math.nan, math.inf, -math.inf, 1e12, -1e300]))
anything = st.tuples(wild, wild, wild, st.floats(-40, 40), st.floats(-40, 40), st.floats(-80, 80))


@pytest.mark.filterwarnings("error")
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.one_of(reachable, anything), st.integers(0, 400)), min_size=1, max_size=4))
def test_random_targets_are_refused_or_reached_and_setpoints_stay_safe(make_rig, targets):
    """Whatever is asked (out of the workspace, NaN, huge, mid-move), every set-point
    sent is inside the stroke and no faster than the leg velocity limit; a refused move
    changes nothing."""
    rig = make_rig().enabled()
    last_accepted = None
    for pose, wait in targets:
        before = rig.controller.snapshot.epoch
        result = rig.controller.move(list(pose))
        event("accepted" if result.ok else f"refused: {result.error}")
        if result.ok:
            last_accepted = result.details["goal"]
        else:
            assert rig.controller.snapshot.epoch == before
        rig.run(wait)
    rig.settle()
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0
    if last_accepted is not None:
        assert rig.controller.telemetry().pose_command == pytest.approx(last_accepted, abs=1e-6)
