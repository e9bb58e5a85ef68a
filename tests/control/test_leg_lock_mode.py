"""Leg-lock mode: the locked leg's set-point never changes, the others move on the constraint."""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, LegLock, PlanningContext, Waypoint, plan_path, project_locked
from hexactl.control.trajectory import KinematicState
from hexactl.kinematics.axes import RelativeMmDeg, RelativeMmRad
from hexactl.kinematics.inverse import leg_lengths, sensor_setpoints
from hexactl.kinematics.leg_lock import ProjectionStatus, project_to_locked_leg
from hexactl.kinematics.pose import absolute_from_relative


def _locked(rig, leg):
    assert rig.controller.leg_lock(leg).ok
    rig.run(3)
    assert rig.controller.telemetry().locked_leg == leg
    return rig.sent.shape[0], rig.controller.snapshot.lock.sensor_mm


@pytest.mark.parametrize("leg", [1, 4])
def test_the_locked_leg_holds_exactly_while_the_others_move_on_the_constraint(make_rig, geometry, leg):
    rig = make_rig(start_pose=(20, 10, 30, 1, -1, 2)).enabled()
    rig.run(5)
    index, locked = _locked(rig, leg)
    result = rig.controller.move([60, 30, 30, 1, -1, 5])
    assert result.ok
    goal = result.details["goal"]
    length = geometry.zero_lengths[leg - 1] + locked
    assert leg_lengths(geometry.legs, absolute_from_relative(geometry.home, goal))[leg - 1] == pytest.approx(length, abs=1e-6)
    rig.settle()
    rig.run(50)
    sent = rig.sent[index:]
    assert np.all(sent[:, leg - 1] == locked)  # bit for bit
    others = [i for i in range(6) if i != leg - 1]
    assert np.ptp(sent[:, others], axis=0).max() > 5.0  # the others did move
    # Every commanded pose on the way kept the locked length: check the set-points' FK.
    telemetry = rig.controller.telemetry()
    assert telemetry.pose_command == pytest.approx(goal, abs=1e-9)
    command = absolute_from_relative(geometry.home, telemetry.pose_command)
    assert leg_lengths(geometry.legs, command)[leg - 1] == pytest.approx(length, abs=1e-6)
    assert rig.actuators.read_feedback().actuators[leg - 1].state.name == "LOCKED"
    rig.assert_setpoints_safe()
    assert telemetry.loop.guard_clamps == 0


def test_a_goal_far_from_the_constraint_is_refused(rig):
    rig.enabled()
    _locked(rig, 2)
    result = rig.controller.move([0, 0, 200, 0, 0, 0])  # every leg gets much longer
    assert not result.ok and result.error == "lock_unreachable"
    assert result.details["correction_mm"] > rig.controller.config.lock_max_correction_mm
    assert result.message.endswith("ask for a goal nearer that pose (details: nearest_pose), or unlock leg 2 to go "
                                   "there"), result.message  # found from outside: no remedy was given
    assert len(result.details["nearest_pose"]) == 6


def test_unlock_is_bumpless_and_the_leg_follows_again(rig):
    rig.enabled()
    index, locked = _locked(rig, 3)
    assert rig.controller.move([40, 0, 0, 0, 0, 2]).ok
    rig.settle()
    pose = rig.controller.telemetry().pose_command
    before = rig.sent[-1].copy()
    assert rig.controller.leg_unlock().ok
    rig.run(20)
    after = rig.sent[-20:]
    assert np.max(np.abs(after - before)) < 1e-6  # no step on release
    assert rig.controller.telemetry().pose_command == pytest.approx(pose, abs=1e-9)
    assert rig.controller.telemetry().locked_leg is None
    assert rig.controller.move([0, 0, 50, 0, 0, 0]).ok
    rig.settle()
    assert np.ptp(rig.sent[-500:, 2]) > 1.0  # leg 3 moves again
    rig.assert_setpoints_safe()


def test_disable_and_reset_say_that_they_end_the_lock(rig):
    rig.enabled()
    _locked(rig, 3)
    disabled = rig.controller.disable()
    assert disabled.ok and disabled.message == "disabled; leg 3 is no longer locked: the next enable drives all six legs"
    rig.run(3)
    assert rig.controller.telemetry().locked_leg is None
    rig.enabled()
    _locked(rig, 2)
    assert rig.controller.estop().ok
    rig.run(3)
    reset = rig.controller.reset()
    assert reset.ok and reset.message == "reset to disabled; leg 2 is no longer locked: the next enable drives all six legs"
    rig.run(3)
    assert rig.controller.telemetry().locked_leg is None
    assert rig.controller.reset().message == "reset to disabled"  # no lock: nothing more to say


def test_a_calibration_change_while_locked_and_latched_says_to_reset(rig, geometry):
    # Found from outside: locked, then E-stopped, `load-calibration` said "unlock before
    # changing the calibration", and `unlock` answered "estop is latched: reset first".
    rig.enabled()
    _locked(rig, 4)
    assert rig.controller.estop().ok
    rig.run(3)
    assert rig.controller.telemetry().locked_leg == 4  # the drive stays braked until the reset
    zero = list(geometry.zero_lengths)
    zero[0] += 2.0
    calibrated = geometry.model_copy(update={"zero_lengths": tuple(zero)})
    refused = rig.controller.load_calibration(calibrated, "cal-1")
    assert refused.error == "leg_locked"
    assert refused.message == "leg 4 is locked and estop is latched: reset (which ends the lock) before changing the calibration"
    assert rig.controller.reset().ok
    rig.run(3)
    assert rig.controller.load_calibration(calibrated, "cal-1").ok


def test_lock_preconditions(rig):
    assert rig.controller.leg_lock(1).error == "not_enabled"
    # disabled, no leg is locked: not "enable first", which would not give unlock anything to do
    assert (rig.controller.leg_unlock().error, rig.controller.leg_unlock().message) == ("not_locked", "no leg is locked")
    rig.enabled()
    for leg in (0, 7, "1", 2.0, True, None):
        assert rig.controller.leg_lock(leg).error == "invalid_argument"
    assert rig.controller.leg_unlock().error == "not_locked"
    assert rig.controller.move([300, 0, 0, 0, 0, 0]).ok
    rig.run(10)
    assert rig.controller.leg_lock(1).error == "busy"  # moving
    rig.settle()
    _locked(rig, 1)
    assert rig.controller.leg_lock(2).error == "leg_locked"


def test_an_actuator_that_does_not_lock_faults(rig):
    rig.enabled()
    rig.actuators._apply = lambda i, command: None  # ignores every command from now on
    assert rig.controller.leg_lock(5).ok
    rig.run_until(lambda: rig.controller.snapshot.state.value == "fault",
                  limit=int(0.6e9 / rig.period_ns))
    fault = rig.controller.snapshot.faults[0]
    assert fault.code == "actuator_state" and fault.leg == 5


def test_a_move_whose_path_strays_far_from_the_constraint_runs_to_the_end(rig, geometry):
    """Leg 3 locked in the zero posture, roll −15°, pitch −15°, yaw −30°: the goal is
    1.5 mm from the constraint, the straight line to it 26 mm at worst. The loop used to
    project each cycle's target from the target itself with its three iterations, too few
    that far, and faulted mid-move (leg_lock_projection); it tracks from the cycle before."""
    rig.enabled()
    index, locked = _locked(rig, 3)
    result = rig.controller.move([0, 0, 0, -15, -15, -30])
    assert result.ok, result.message
    goal = result.details["goal"]
    middle = absolute_from_relative(geometry.home, np.array(goal) / 2)
    cold = project_to_locked_leg(geometry.legs, middle, 3, geometry.zero_lengths[2] + locked,
                                 geometry.characteristic_length_mm,
                                 max_iterations=rig.controller.config.lock_cycle_iterations)
    assert cold.status is ProjectionStatus.MAX_ITERATIONS  # beyond the old per-cycle projection's reach
    rig.settle()
    snapshot = rig.controller.snapshot
    assert snapshot.state.value == "enabled" and snapshot.faults == ()
    assert rig.controller.telemetry().pose_command == pytest.approx(goal, abs=1e-9)
    assert np.all(rig.sent[index:, 2] == locked)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_planning_refuses_a_path_the_loops_iterations_cannot_follow(geometry):
    """Planning projects every cycle's target with the loop's own procedure and iteration
    budget: with one iteration per cycle no real move converges, and it says so instead of
    letting the loop fault."""
    active = ActiveGeometry.of(geometry, "nominal")
    lock = LegLock(3, sensor_setpoints(geometry.legs, active.absolute_from_relative_mm_rad([0.0] * 6))[2])
    config = ControllerConfig()
    context = PlanningContext(active, config.motion, config.loop.period_s, geometry.limits.leg_velocity_mm_s, lock,
                              lock_cycle_iterations=1)
    plan = plan_path(context, KinematicState.at_rest(RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)), [Waypoint([0, 0, 0, -15, -15, -30])])
    assert plan.refusal is not None and plan.refusal.code == "lock_unreachable"
    assert "the loop cannot keep leg 3 at its locked length" in plan.refusal.message
    assert plan.refusal.details["t_s"] > 0
    assert plan_path(replace(context, lock_cycle_iterations=config.lock_cycle_iterations),
                     KinematicState.at_rest(RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)), [Waypoint([0, 0, 0, -15, -15, -30])]).ok


# Mostly rotation (to 80 % of the envelope's), little translation (a quarter of it): the
# straight lines that stray farthest from the constraint; one in seven used to fault.
locked_moves = st.tuples(*[st.floats(-fraction * limit, fraction * limit)
                           for fraction, limit in zip((0.25, 0.25, 0.25, 0.8, 0.8, 0.8), (600, 600, 250, 23, 23, 60))])


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(leg=st.integers(1, 6), first=locked_moves, second=locked_moves)
def test_leg_lock_moves_planning_accepts_run_to_the_end(make_rig, leg, first, second):
    """Two moves in leg-lock mode: each is refused at planning or reaches its goal with no
    fault. The requests are the goals' nearest poses on the constraint, so that most get
    past the goal check and it is the paths that are tried."""
    rig = make_rig().enabled()
    _locked(rig, leg)
    for request in (first, second):
        checked = rig.controller.validate_pose(request)
        if not checked.ok and "nearest_pose" in checked.details:
            request = checked.details["nearest_pose"]
        result = rig.controller.move(request)
        if not result.ok:
            assert result.error in ("path_violation", "lock_unreachable"), result.message
            continue
        rig.settle()
        snapshot = rig.controller.snapshot
        assert snapshot.state.value == "enabled" and snapshot.faults == (), snapshot.faults
        assert rig.controller.telemetry().pose_command == pytest.approx(result.details["goal"], abs=1e-6)
    rig.assert_setpoints_safe()
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_a_sequence_played_with_a_leg_locked_says_how_far_each_waypoint_is_moved(rig):
    """Found from outside: a sequence played with a leg locked went to projected waypoints,
    up to 25 mm from the file's, and neither play nor its validation said how far."""
    from hexactl.control.sequences import sequence_from_mapping

    sequence = sequence_from_mapping({"name": "steps", "waypoint": [
        {"pose": [0, 0, 0, 0, 0, 0]}, {"pose": [0, 0, 8, 0, 0, 0]}, {"pose": [15, 0, 0, 0, 0, 0]}]})
    rig.enabled()
    assert "lock_corrections_mm" not in rig.controller.validate_sequence(sequence).details  # no leg locked
    _locked(rig, 2)
    validated = rig.controller.validate_sequence(sequence)
    assert validated.ok, validated.message
    at_rest, up, aside = validated.details["lock_corrections_mm"]
    assert at_rest == pytest.approx(0.0, abs=1e-6)  # the lock was taken there: on the constraint
    assert up > 1.0  # every leg longer: the locked one cannot follow, the goal moves
    assert 0.0 <= aside < rig.controller.config.lock_max_correction_mm
    # Each is the projection of that waypoint alone onto the lock, as a move's goal is.
    snapshot = rig.controller.snapshot
    for pose, correction in zip(([0, 0, 8, 0, 0, 0], [15, 0, 0, 0, 0, 0]), (up, aside)):
        projected = project_locked(snapshot.active, snapshot.lock, RelativeMmDeg(*pose).in_radians())
        assert projected.correction == pytest.approx(correction, rel=1e-6, abs=1e-6)
    played = rig.controller.play(sequence)
    assert played.ok and played.details["lock_corrections_mm"] == pytest.approx(validated.details["lock_corrections_mm"])
