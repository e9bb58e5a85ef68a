"""Motion in the operator's frames: the pivot point stays put along the whole path, a
relative move in the tool frame is the composed absolute one, soft limits only narrow the
hardware's, and the loop follows frames safely (issue 12)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from hexactl.control.config import ControllerConfig
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.jog_planning import JOG_HORIZON_S
from hexactl.control.sequences import sequence_from_mapping
from hexactl.control.waves import WaveSpec
from hexactl.control.planning import (
    OUTSIDE_SOFT_LIMITS,
    ActiveGeometry,
    PlanningContext,
    path_violations,
    pose_allowed,
)
from hexactl.kinematics.axes import ToolInWorkMmDeg
from hexactl.kinematics.frames import apply, compose, pose_of, transform_of
from hexactl.kinematics.soft_limits import SoftLimits

TOOL_ABOVE = OperatorFrames(work=(0, 0, 300, 0, 0, 0), tool=(0, 0, 300, 0, 0, 0))
"""A tool point 300 mm above the platform's origin, and the work frame on it at the zero
posture: work pose 0 is the zero posture."""

MICROMETRE = 1e-3


def _tool_point(rig, frames: OperatorFrames) -> tuple[float, float, float]:
    """Where the tool frame's origin is in the fixed frame, by the pose commanded this cycle."""
    s = rig.controller.snapshot
    absolute = np.asarray(s.active.home) + np.asarray(s.pose_command)
    return apply(transform_of(absolute), frames.frames(s.active.home).tool.translation)


def test_a_rotation_about_a_tool_point_keeps_it_put_every_cycle_of_the_path(rig):
    """Done-when: 10° about a point 300 mm above the platform, within 1 µm all along."""
    assert rig.controller.set_frames(TOOL_ABOVE).ok
    rig.enabled()
    before = _tool_point(rig, TOOL_ABOVE)
    moved = rig.controller.move([0, 0, 0, 10, 0, 0], frame=Frame.WORK)
    assert moved.ok and moved.details["tool_goal"] == pytest.approx([0, 0, 0, 10, 0, 0], abs=1e-9)
    deviations, cycles = [], 0
    while True:
        rig.run()
        cycles += 1
        deviations.append(np.linalg.norm(np.subtract(_tool_point(rig, TOOL_ABOVE), before)))
        if rig.controller.snapshot.motion.value == "holding":
            break
    assert cycles > 100  # a real path, not a jump
    assert max(deviations) < MICROMETRE
    assert rig.controller.telemetry().pose_command[3] == pytest.approx(10.0, abs=1e-9)
    # The platform's own origin swept an arc: about 300 mm × sin 10° sideways.
    assert abs(rig.controller.telemetry().pose_command[1]) == pytest.approx(300 * np.sin(np.radians(10)), rel=1e-6)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_the_same_rotation_about_the_platform_origin_moves_the_tool_point(rig):
    """The control experiment: in the zero frame the rotation turns about the platform's
    origin, and the point 300 mm above it swings."""
    rig.enabled()
    before = _tool_point(rig, TOOL_ABOVE)
    assert rig.controller.move([0, 0, 0, 10, 0, 0]).ok
    rig.settle()
    assert np.linalg.norm(np.subtract(_tool_point(rig, TOOL_ABOVE), before)) > 50.0


def test_a_relative_move_in_the_tool_frame_equals_the_composed_absolute_move(make_rig):
    frames = OperatorFrames(work=(20, -10, 300, 0, 0, 15), tool=(5, 0, 300, 0, 3, 0))
    displacement = (10.0, -5.0, 4.0, 2.0, -3.0, 5.0)
    relative, absolute = make_rig(), make_rig()
    for rig in (relative, absolute):
        assert rig.controller.set_frames(frames).ok
        rig.enabled()
        assert rig.controller.move([30, 20, 10, 1, 2, 3], frame=Frame.WORK).ok
        rig.settle()
    start = absolute.controller.telemetry().tool_pose_command
    composed = compose(transform_of(ToolInWorkMmDeg(*start).in_radians()),
                       transform_of(ToolInWorkMmDeg(*displacement).in_radians()))
    goal = np.array(pose_of(composed))
    goal[3:] = np.degrees(goal[3:])
    by_relative = relative.controller.move(displacement, frame=Frame.TOOL, relative=True)
    by_absolute = absolute.controller.move(list(goal), frame=Frame.WORK)
    assert by_relative.ok and by_absolute.ok
    assert by_relative.details["tool_goal"] == pytest.approx(by_absolute.details["tool_goal"], abs=1e-9)
    for rig in (relative, absolute):
        rig.settle()
    assert relative.controller.telemetry().pose_command == pytest.approx(absolute.controller.telemetry().pose_command,
                                                                         abs=1e-9)
    assert relative.controller.telemetry().tool_pose_command == pytest.approx(tuple(goal), abs=1e-6)


def test_relative_moves_in_the_work_and_zero_frames_add_component_by_component(rig):
    assert rig.controller.set_frames(TOOL_ABOVE).ok
    rig.enabled()
    assert rig.controller.move([0, 0, 0, 5, 0, 0], frame=Frame.WORK).ok
    rig.settle()
    work = rig.controller.move([10, 0, -5, 0, 2, 0], frame=Frame.WORK, relative=True)
    assert work.details["tool_goal"] == pytest.approx([10, 0, -5, 5, 2, 0], abs=1e-9)
    rig.settle()
    before = rig.controller.telemetry().pose_command
    zero = rig.controller.move([0, 3, 0, 0, 0, -1], relative=True)
    assert zero.details["goal"] == pytest.approx(np.add(before, [0, 3, 0, 0, 0, -1]), abs=1e-9)
    rig.settle()
    rig.assert_setpoints_safe()


def test_an_absolute_pose_in_the_tool_frame_is_refused_with_the_reason(rig):
    rig.enabled()
    refused = rig.controller.move([1, 0, 0, 0, 0, 0], frame=Frame.TOOL)
    assert refused.error == "invalid_argument" and "relative move" in refused.message


def test_a_move_in_another_frame_waits_for_rest_and_the_running_one_goes_on(rig):
    assert rig.controller.set_frames(TOOL_ABOVE).ok
    rig.enabled()
    assert rig.controller.move([200, 0, 0, 0, 0, 0]).ok
    rig.run(50)
    refused = rig.controller.move([0, 0, 0, 5, 0, 0], frame=Frame.WORK)
    assert refused.error == "busy" and "another frame" in refused.message
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((200, 0, 0, 0, 0, 0), abs=1e-9)
    assert rig.controller.move([0, 0, 0, 5, 0, 0], frame=Frame.WORK).ok  # at rest: taken
    rig.settle()
    assert rig.controller.telemetry().tool_pose_command == pytest.approx((0, 0, 0, 5, 0, 0), abs=1e-6)
    rig.assert_setpoints_safe()


def test_frames_and_soft_limits_change_only_at_rest(rig):
    """New soft limits set under way would neither stop the motion (it keeps the limits it
    was planned in) nor let the platform back inside afterwards: refused until rest."""
    assert rig.controller.set_frames(TOOL_ABOVE).ok
    rig.enabled()
    before = _tool_point(rig, TOOL_ABOVE)
    assert rig.controller.move([0, 0, 0, 8, 0, 0], frame=Frame.WORK).ok
    rig.run(20)
    refused = rig.controller.set_frames(OperatorFrames(tool=(0, 0, 100, 0, 0, 0)))
    rig.run(20)
    assert np.linalg.norm(np.subtract(_tool_point(rig, TOOL_ABOVE), before)) < MICROMETRE  # the turn about it goes on
    assert refused.error == "busy" and "the platform is moving: wait until it is at rest, or stop it: frames and soft " \
        "limits change only at rest" in refused.message
    rig.settle()
    assert rig.controller.move([300, 0, 0, 0, 0, 0]).ok
    rig.run(20)
    narrow = OperatorFrames(soft_limits=SoftLimits(lower=(-50,) + (None,) * 5, upper=(50,) + (None,) * 5))
    assert rig.controller.set_frames(narrow).error == "busy"
    assert rig.controller.operator_frames() == TOOL_ABOVE
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((300, 0, 0, 0, 0, 0), abs=1e-9)
    assert rig.controller.set_frames(narrow).error == "outside_soft_limits"  # at rest: the usual check
    assert rig.controller.move([0, 0, 0, 0, 0, 0]).ok
    rig.settle()
    assert rig.controller.set_frames(narrow).ok
    rig.assert_setpoints_safe()


def test_frames_wait_for_a_paused_sequence_to_end(rig):
    rig.enabled()
    assert rig.controller.play("x_sweep").ok
    rig.run(40)
    assert rig.controller.pause().ok
    rig.run_until(lambda: rig.controller.telemetry().motion == "holding")
    refused = rig.controller.set_frames(TOOL_ABOVE)
    assert refused.error == "busy" and "sequence 'x_sweep' is paused: abort it first" in refused.message
    assert rig.controller.move([1, 0, 0, 0, 0, 0]).message.startswith("sequence 'x_sweep' is paused")
    assert rig.controller.abort().ok
    rig.settle()
    assert rig.controller.set_frames(TOOL_ABOVE).ok


def test_soft_limits_name_the_limit_and_cannot_be_set_around_a_platform_outside_them(rig):
    limits = SoftLimits(lower=(-50, None, None, None, None, None), upper=(50, None, None, None, None, None),
                        max_tilt_deg=5)
    assert rig.controller.set_frames(OperatorFrames(soft_limits=limits)).ok
    rig.enabled()
    refused = rig.controller.move([80, 0, 0, 0, 0, 0])
    assert refused.error == "path_violation"
    assert [(v["kind"], v["axis"]) for v in refused.details["violations"]] == [("soft_limit", "x")]
    assert "above the soft limit 50 mm" in refused.message
    tilted = rig.controller.validate_pose([0, 0, 0, 4, 4, 0])
    assert tilted.error == "path_violation" and tilted.details["violations"][0]["kind"] == "soft_tilt"
    assert rig.controller.move([40, 0, 0, 0, 0, 0]).ok
    rig.settle()
    narrower = OperatorFrames(soft_limits=SoftLimits(upper=(30, None, None, None, None, None)))
    outside = rig.controller.set_frames(narrower)
    assert outside.error == "outside_soft_limits" and "the tool's x in the work frame, 40.000 mm, above the soft limit 30 mm" in outside.message
    assert rig.controller.operator_frames().soft_limits == limits  # unchanged
    assert OUTSIDE_SOFT_LIMITS not in refused.message  # it started inside them


def test_setting_and_clearing_frames_are_in_the_loops_log_with_who_did_it(rig):
    """Found from outside: a change of the soft limits, their removal included, left no
    event, so nothing said who removed them."""
    from hexactl.control.submitter import commands_from

    frames = OperatorFrames(work=(0, 0, 300, 0, 0, 30), tool=(0, 0, 300, 0, 0, 0),
                            soft_limits=SoftLimits(lower=(-10,) + (None,) * 5, upper=(25,) + (None,) * 5,
                                                   max_tilt_deg=8))
    with commands_from("hexactl ann@bench-2"):
        assert rig.controller.set_frames(frames).ok
    with commands_from("hexactl bob@bench-3"):
        assert rig.controller.set_frames(OperatorFrames()).ok
    rig.run()
    events = [(e.code, e.message, e.sender) for e in rig.controller.snapshot.events if e.code == "frames_set"]
    assert events == [
        ("frames_set", "work frame (0, 0, 300, 0, 0, 30), tool frame (0, 0, 300, 0, 0, 0) (mm, deg); soft limits "
                       "x -10..25 mm, tilt ≤ 8 deg", "hexactl ann@bench-2"),
        ("frames_set", "none: no work frame, no tool frame, no soft limits", "hexactl bob@bench-3")]

def test_a_platform_outside_restored_soft_limits_may_come_back_never_go_further(rig):
    """Soft limits restored at start-up around another pose than the platform's: a move or
    a jog back inside is planned (every motion was refused, the way back included, and the
    only way out was to clear them); one further out is refused, saying why."""
    rig.enabled()
    assert rig.controller.move([-10, 0, 0, 0, 0, 0]).ok
    rig.settle()
    restored = OperatorFrames(soft_limits=SoftLimits(lower=(-5, None, None, None, None, None),
                                                     upper=(650, None, None, None, None, None)))
    rig.controller.frames.current = restored  # as the service's start-up restores them, unchecked
    assert rig.controller.validate_pose([-10, 5, 0, 0, 0, 0]).ok  # along the bound: no further out
    for refused in (rig.controller.validate_pose([-12, 0, 0, 0, 0, 0]),
                    rig.controller.jog([-5, 0, 0, 0, 0, 0]),
                    rig.controller.validate_wave(WaveSpec(frequency_hz=0.5, cycles=2, axes={"z": {"amplitude": 1.0}}))):
        assert refused.error == "path_violation" and "below the soft limit -5 mm" in refused.message, refused
        assert OUTSIDE_SOFT_LIMITS in refused.message, refused.message
    assert rig.controller.jog([5, 0, 0, 0, 0, 0]).ok  # back inside
    assert rig.controller.stop().ok
    rig.settle()
    assert rig.controller.move([0, 0, 0, 0, 0, 0]).ok
    rig.settle()
    assert rig.controller.snapshot.pose_command == pytest.approx((0,) * 6, abs=1e-9)


def test_held_a_hair_beyond_a_soft_limit_the_platform_is_not_locked_out(rig):
    """Found from outside: jogged onto a soft limit, E-stopped, reset and enabled again, the
    platform held the pose its readings gave, 1.2 µm beyond the limit, and every move was
    refused, the move back inside included."""
    limit = 20.0
    assert rig.controller.set_frames(OperatorFrames(soft_limits=SoftLimits(upper=(limit,) + (None,) * 5))).ok
    rig.enabled()
    assert rig.controller.move([limit + 0.0012, 0, 0, 0, 0, 0], relative=False).error == "path_violation"
    rig.controller.frames.current = OperatorFrames()  # to put it there; then the limit, as the service kept it
    assert rig.controller.move([limit + 0.0012, 0, 0, 0, 0, 0]).ok
    rig.settle()
    rig.controller.frames.current = OperatorFrames(soft_limits=SoftLimits(upper=(limit,) + (None,) * 5))
    further = rig.controller.validate_pose([limit + 0.01, 0, 0, 0, 0, 0])
    assert further.error == "path_violation" and "above the soft limit 20 mm" in further.message
    assert rig.controller.validate_pose([0, 0, 5, 0, 0, 0], relative=True).ok  # along it: no further out
    lower = rig.controller.validate_pose([-limit - 0.0012, 0, 0, 0, 0, 0])  # as far past the other bound: no
    assert lower.ok  # x has no lower bound here
    assert rig.controller.jog([1, 0, 0, 0, 0, 0]).error == "path_violation"
    assert rig.controller.move([10, 0, 0, 0, 0, 0]).ok
    rig.settle()
    assert rig.controller.snapshot.pose_command[0] == pytest.approx(10.0, abs=1e-9)
    assert rig.controller.jog([1, 0, 0, 0, 0, 0]).ok  # inside: it heads for the limit again


WINDOW = OperatorFrames(work=(141.4214, 0, 0, 0, 0, 45), soft_limits=SoftLimits(lower=(5,) + (None,) * 5,
                                                                               upper=(6,) + (None,) * 5))
"""A 1 mm window on the work frame's x, which reads -100 at the zero posture: 105 mm below it."""


def test_from_below_a_soft_window_nothing_goes_past_its_upper_bound(rig):
    """Found from outside: the start's excess was kept per axis, not per bound, so a
    platform 105 mm below x's lower bound was let 105 mm past the upper one: a move blended
    from the one under way overshot it by up to 19 mm. Then a slow jog back inside was
    refused, its horizon still outside, and a jog into the window planned past it."""
    rig.enabled()
    rig.controller.frames.current = WINDOW  # as the service's start-up restores them, unchecked
    assert rig.controller.jog([0.5, 0, 0, 0, 0, 0], frame=Frame.WORK).ok  # 2 mm in its 4 s horizon: still outside
    assert rig.controller.stop().ok
    rig.settle()
    jog = rig.controller.jog([50, 0, 0, 0, 0, 0], frame=Frame.WORK)  # 105 mm to go: the window in its horizon
    assert jog.ok and jog.details["end"] == "the soft limit on x at 6 mm", jog
    assert rig.controller.stop().ok
    rig.settle()
    assert rig.controller.move([-200, 349.2, 0, 0, 0, 0]).ok  # to work x 5.5
    rig.run(750)
    blended = rig.controller.move([300, -150.8, 0, 0, 0, 0])  # to work x 5.5 again, turning from the first
    assert blended.error == "path_violation" and "above the soft limit 6 mm" in blended.message, blended
    rig.settle()
    tool_x = rig.controller.telemetry().tool_pose_command[0]
    assert 5 <= tool_x <= 6, tool_x

def test_a_tool_mounted_backwards_is_held_in_a_yaw_window_up_to_180(rig):
    """A tool frame at yaw -180 reads yaw -180 at the zero posture: soft limits yaw
    [170, 180] were refused there (-180 below 170), the tool inside its window; turned past
    180 it was said to be below 170, and a jog towards 180 to head for 170."""
    backwards = OperatorFrames(tool=(0, 0, 300, 0, 0, -180), work=(0, 0, 300, 0, 0, 0),
                               soft_limits=SoftLimits(lower=(None,) * 5 + (170,), upper=(None,) * 5 + (180,)))
    assert rig.controller.set_frames(backwards).ok
    rig.enabled()
    assert rig.controller.move([0, 0, 0, 0, 0, -5], frame=Frame.WORK, relative=True).ok
    rig.settle()
    assert rig.controller.move([0, 0, 0, 0, 0, 5], frame=Frame.WORK, relative=True).ok
    rig.settle()
    beyond = rig.controller.validate_pose([0, 0, 0, 0, 0, 1], frame=Frame.WORK, relative=True)
    assert beyond.error == "path_violation" and "the tool's yaw in the work frame, 181.000 deg, above the soft limit 180 deg" in beyond.message
    assert rig.controller.move([0, 0, 0, 0, 0, -5], frame=Frame.WORK, relative=True).ok
    rig.settle()
    jog = rig.controller.jog([0, 0, 0, 0, 0, 2], frame=Frame.WORK)  # it said: the soft limit on yaw at 170
    assert jog.ok and jog.details["end"] == "the soft limit on yaw at 180 deg"


def test_a_goal_on_a_soft_limit_is_accepted_whatever_its_path_rounds_to(rig):
    """A goal on a soft bound, with a rotation on the way, was refused: its path's samples
    ended an ulp beyond the bound ("x 50.000 mm above the soft limit 50 mm"). A micrometre
    beyond is still beyond."""
    limits = SoftLimits(lower=(-400.0,) * 3 + (None,) * 3, upper=(50.0, 7.3, 123.456, None, None, None))
    assert rig.controller.set_frames(OperatorFrames(soft_limits=limits)).ok
    for goal in ([50.0, 3.3, 0, 2.258172906097336, 0, 0], [0, 7.3, -17.0, -11.248758506492456, 0, 0],
                 [-17.0, 0, 123.456, 13.847896737132508, 0, 0]):
        assert rig.controller.validate_pose(goal).ok, (goal, rig.controller.validate_pose(goal).message)
    refused = rig.controller.validate_pose([50.001, 0, 0, 0, 0, 0])
    assert not refused.ok and "the tool's x in the work frame, 50.001 mm, above the soft limit 50 mm" in refused.message


axis_values = st.floats(-700.0, 700.0)
angle_values = st.floats(-30.0, 30.0)
goal_poses = st.tuples(axis_values, axis_values, st.floats(-300.0, 300.0), angle_values, angle_values, angle_values)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(goal=goal_poses, low=st.tuples(*[st.floats(-400.0, -1.0)] * 3), high=st.tuples(*[st.floats(1.0, 400.0)] * 3),
       tilt=st.floats(1.0, 90.0))
def test_soft_limits_never_allow_what_the_hardware_refuses(rig, goal, low, high, tilt):
    """A soft limit can only narrow: whatever is accepted with soft limits is accepted
    without them; and a pose the soft limits break is refused with them."""
    rig.controller.set_frames(OperatorFrames())
    hardware = rig.controller.validate_pose(list(goal))
    limits = SoftLimits(lower=(*low, None, None, None), upper=(*high, None, None, None), max_tilt_deg=tilt)
    assert rig.controller.set_frames(OperatorFrames(soft_limits=limits)).ok  # the platform rests at 0: inside
    soft = rig.controller.validate_pose(list(goal))
    if soft.ok:
        assert hardware.ok
    if limits.violations([goal])[0]:
        assert not soft.ok
    elif hardware.ok:
        assert soft.ok


def test_a_sequence_in_the_work_frame_turns_about_the_pivot_at_every_waypoint(rig):
    from hexactl.control.sequences import MotionSequence

    assert rig.controller.set_frames(TOOL_ABOVE).ok
    rig.enabled()
    assert rig.controller.move([0, 0, 0, 0, 0, 1]).ok  # the sequence starts from rest in other coordinates
    rig.settle()
    tilts = MotionSequence(name="tilts", frame="work", waypoints=[
        {"pose": [0, 0, 0, 6, 0, 0], "dwell": 0.01}, {"pose": [0, 0, 0, 0, -6, 0], "dwell": 0.01},
        {"pose": [0, 0, 0, 0, 0, 0]}])
    assert rig.controller.validate_sequence(tilts).ok
    pivot = _tool_point(rig, TOOL_ABOVE)  # yawed about the platform's axis, which runs through it
    assert rig.controller.play(tilts).ok
    deviations = []
    while not deviations or rig.controller.snapshot.sequence is not None:
        rig.run()
        deviations.append(np.linalg.norm(np.subtract(_tool_point(rig, TOOL_ABOVE), pivot)))
    assert len(deviations) > 100 and max(deviations) < MICROMETRE
    records = rig.controller.sequence_records().records
    assert len(records) == 3 and records[0].pose_command[3] == pytest.approx(6.0, abs=1e-9)  # dwell records: zero frame
    rig.assert_setpoints_safe()


frame_poses = st.tuples(*[st.floats(-300.0, 300.0)] * 3, *[st.floats(-30.0, 30.0)] * 3)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(pose=st.tuples(*[st.floats(-700.0, 700.0)] * 3, *[st.floats(-0.5, 0.5)] * 3), work=frame_poses, tool=frame_poses,
       box=st.floats(10.0, 600.0), tilt=st.one_of(st.none(), st.floats(1.0, 30.0)))
def test_one_pose_is_allowed_exactly_when_no_path_violation_is_found_there(geometry, pose, work, tool, box, tilt):
    """The stream's per-target check (plain floats) and every plan's check (numpy) agree,
    hardware and soft limits in the operator's frames alike."""
    active = ActiveGeometry.of(geometry, "nominal")
    operator = OperatorFrames(work=work, tool=tool, soft_limits=SoftLimits(lower=(-box,) * 3 + (None,) * 3,
                                                                           upper=(box,) * 3 + (None,) * 3, max_tilt_deg=tilt))
    config = ControllerConfig()
    context = PlanningContext(active, config.motion, config.loop.period_s, geometry.limits.leg_velocity_mm_s,
                              frames=operator.frames(active.home), soft_limits=operator.soft_limits)
    violations = path_violations(context, np.array([pose]), 0)
    assume(all(abs(v.value - v.limit) > 1e-6 for v in violations))  # on a bound, the two paths' rounding may differ
    assert pose_allowed(context, pose) == (not violations), [v.message for v in violations]


@pytest.mark.parametrize("frame", [Frame.WORK, Frame.TOOL])
def test_relative_moves_and_jogs_turn_by_what_was_asked_across_180_degrees(rig, frame):
    """A work frame turned 170° about z: the tool's yaw in it starts at -170°, and a turn
    of -15° takes it to -185°, which read back is +175°. The next relative turn and a jog
    go on from there by what they ask, not the long way round through the hardware's
    limits (a base read back into (-180°, 180°] made +5° a turn of 365°, refused)."""
    assert rig.controller.set_frames(OperatorFrames(work=(0, 0, 0, 0, 0, 170))).ok
    rig.enabled()
    assert rig.controller.move([0, 0, 0, 0, 0, -15], frame=frame, relative=True).ok
    rig.settle()
    assert rig.controller.telemetry().pose_command[5] == pytest.approx(-15, abs=1e-9)
    turned = rig.controller.move([0, 0, 0, 0, 0, 5], frame=frame, relative=True)
    assert turned.ok, turned.message
    rig.settle()
    assert rig.controller.telemetry().pose_command[5] == pytest.approx(-10, abs=1e-9)
    jogged = rig.controller.jog([0, 0, 0, 0, 0, -2], frame)
    assert jogged.ok, jogged.message
    assert jogged.details["goal"][5] == pytest.approx(-10 - 2 * JOG_HORIZON_S, abs=1e-9)  # no limit that near
    rig.assert_setpoints_safe()


def test_an_absolute_pose_in_a_work_frame_turned_180_degrees_is_reached_the_short_way(rig):
    """A work frame turned 180° about z (the part faces the other way): the tool's yaw in
    it reads back -180° at the zero posture, and the operator types the 180° he set. The
    same orientation, reached without turning at all, by a move and by a sequence; a
    turn of a few degrees across ±180° is a few degrees (it was a 360° swing, refused)."""
    assert rig.controller.set_frames(OperatorFrames(work=(0, 0, 0, 0, 0, 180))).ok
    rig.enabled()
    assert abs(rig.controller.telemetry().tool_pose_command[5]) == pytest.approx(180, abs=1e-9)
    lifted = rig.controller.move([0, 0, 10, 0, 0, 180], frame=Frame.WORK)
    assert lifted.ok, lifted.message
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((0, 0, 10, 0, 0, 0), abs=1e-9)
    assert rig.controller.move([0, 0, 10, 0, 0, -178], frame=Frame.WORK).ok
    rig.settle()
    assert rig.controller.move([0, 0, 10, 0, 0, 178], frame=Frame.WORK).ok
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((0, 0, 10, 0, 0, -2), abs=1e-9)
    square = {"name": "turned", "frame": "work", "waypoints": [{"pose": [20, 0, 10, 0, 0, 180]},
                                                                {"pose": [20, 0, 10, 0, 0, -179]}]}
    played = rig.controller.play(sequence_from_mapping(square))
    assert played.ok, played.message
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx((-20, 0, 10, 0, 0, 1), abs=1e-9)
    rig.assert_setpoints_safe()


def test_a_relative_turn_beyond_half_a_turn_is_refused_not_taken_the_other_way(rig):
    """+300° is out of reach: refused, never turned into the -60° that ends at the same
    orientation (a goal in the work frame is reached the short way round)."""
    assert rig.controller.set_frames(OperatorFrames(work=(0, 0, 0, 0, 0, 180))).ok
    rig.enabled()
    for frame in Frame:
        refused = rig.controller.move([0, 0, 0, 0, 0, 300], frame=frame, relative=True)
        assert refused.error == "invalid_argument" and refused.message == (
            "a relative turn is at most 180° about each axis, got yaw 300°: the same orientation is yaw -60°")
    # Found from outside: the hint was a fixed "(-200° is +160°)" whatever the turn asked
    refused = rig.controller.move([0, 0, 0, 400, 0, -200], relative=True)
    assert refused.message.endswith("got roll 400°, yaw -200°: the same orientation is roll +40°, yaw +160°"), \
        refused.message
    refused = rig.controller.move([0, 0, 0, 0, 0, 180.0001], relative=True)  # was "got yaw 180°: … is yaw -180°"
    assert refused.message.endswith("got yaw 180.0001°: the same orientation is yaw -179.9999°"), refused.message


def test_telemetry_names_the_soft_limits_the_commanded_pose_breaks(make_rig):
    """Found from outside: a service restored soft limits the platform stood outside of and
    said nothing, in its log or in status, until a move was refused."""
    from hexactl.control.controller import Controller

    rig = make_rig(start_pose=(0, 15, 0, 0, 0, 0))
    limits = OperatorFrames(soft_limits=SoftLimits(upper=(None, 10, None, None, None, None)))
    restored = Controller(rig.controller.thread, config=ControllerConfig(), nominal=rig.geometry, frames=limits)
    outside = restored.telemetry().outside_soft_limits
    assert len(outside) == 1 and outside[0].startswith("the tool's y in the work frame, 15") and "above the soft limit 10 mm" in outside[0], outside
    assert rig.controller.telemetry().outside_soft_limits == ()  # no soft limits: nothing to break
    # as the API publishes it, and hexactl status shows it
    from hexactl.adapters.api.messages import Telemetry
    from hexactl.adapters.api.wire import jsonable
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    record = Telemetry.model_validate(jsonable(restored.telemetry())).model_dump(mode="json")
    assert f"OUTSIDE        {outside[0]}" in format_telemetry(record).splitlines(), format_telemetry(record)


def test_a_refused_path_names_the_poses_axis_first_and_the_legs_after(rig):
    """Found from outside: with the tool frame turned 90° in yaw, a move in the work frame to
    yaw 0 is yaw −90° for the platform; the refusal began with a leg's stroke and named the
    yaw last, after twelve leg lines."""
    assert rig.controller.set_frames(OperatorFrames(tool=(0, 0, 0, 0, 0, 90))).ok
    refused = rig.controller.validate_pose([0, 0, 10, 0, 0, 0], frame=Frame.WORK)
    assert refused.error == "path_violation"
    assert refused.message.startswith("yaw -90 deg outside the pose envelope"), refused.message
    kinds = [violation["kind"] for violation in refused.details["violations"]]
    assert kinds[0] == "pose_range" and len(kinds) > 1 and "pose_range" not in kinds[1:], kinds


def test_a_soft_bound_beyond_where_the_tool_can_go_is_taken_with_a_note(rig) -> None:
    """Found from outside: x -5000..5000 mm was taken without a word, though the envelope
    ends at ±610 mm: a bound that limits nothing, or a unit slip for 50.00."""
    wide = OperatorFrames(soft_limits=SoftLimits(lower=(-5000, -50) + (None,) * 4, upper=(5000, 50) + (None,) * 4))
    result = rig.controller.set_frames(wide)
    assert result.ok and result.message.startswith("frames set; note: x lower bound -5000 mm is beyond where the tool "
                                                   "can go (x -610..610 mm over the pose envelope): it limits nothing")
    assert "x upper bound 5000 mm" in result.message and "y " not in result.message, result.message
    # In a work frame 3 m away the same x reaches 3 m on: a bound there limits something
    moved = OperatorFrames(work=(-3000, 0, 0, 0, 0, 0), soft_limits=SoftLimits(
        lower=(2500,) + (None,) * 5, upper=(3500,) + (None,) * 5))
    assert rig.controller.set_frames(moved).message == "frames set"
