"""Leg-lock mode: the locked leg's set-point never changes, the others move on the constraint."""

import numpy as np
import pytest

from hexactl.kinematics.inverse import leg_lengths
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


def test_lock_preconditions(rig):
    assert rig.controller.leg_lock(1).error == "not_enabled"
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
