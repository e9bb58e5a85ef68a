"""Telemetry's ``goal`` and ``remaining_s``: where the move under way ends and when, counted
down on the loop's clock; None at rest (and the goal while braking)."""

from __future__ import annotations

import pytest

from hexactl.adapters.api.messages import Telemetry as TelemetryMessage
from hexactl.adapters.api.wire import jsonable


def test_a_move_reports_its_goal_and_the_time_left_counting_down_to_rest(rig):
    rig.enabled()
    at_rest = rig.controller.telemetry()
    assert (at_rest.goal, at_rest.remaining_s) == (None, None)
    assert rig.controller.move([0, 0, 20, 0, 0, 5], duration=3.0).ok
    rig.run(2)
    started = rig.controller.telemetry()
    assert started.motion == "moving"
    assert started.goal == pytest.approx((0, 0, 20, 0, 0, 5), abs=1e-9)
    assert started.remaining_s == pytest.approx(3.0, abs=0.02)  # less the cycles since the plan started
    TelemetryMessage.model_validate(jsonable(started))  # the API's record takes the new fields

    cycles = 500
    rig.run(cycles)
    later = rig.controller.telemetry()
    assert later.remaining_s == pytest.approx(started.remaining_s - cycles * rig.period_ns / 1e9, abs=1e-6)
    left = rig.settle()
    assert left * rig.period_ns / 1e9 == pytest.approx(later.remaining_s, abs=2 * rig.period_ns / 1e9)
    done = rig.controller.telemetry()
    assert (done.goal, done.remaining_s) == (None, None)


def test_braking_has_no_goal_but_the_time_to_rest(rig):
    rig.enabled()
    assert rig.controller.move([0, 0, 60, 0, 0, 0], duration=4.0).ok
    rig.run(1000)
    assert rig.controller.stop().ok
    rig.run(2)
    braking = rig.controller.telemetry()
    assert braking.motion == "stopping"
    assert braking.goal is None
    left = rig.settle()
    assert left * rig.period_ns / 1e9 == pytest.approx(braking.remaining_s, abs=2 * rig.period_ns / 1e9)


def test_a_sequence_reports_each_waypoints_goal(rig):
    from hexactl.control.sequences import MotionSequence, SequenceWaypoint

    rig.enabled()
    waypoints = [SequenceWaypoint(pose=[0, 0, z, 0, 0, 0], dwell=0.2, duration=1.0) for z in (10, 20)]
    assert rig.controller.play(MotionSequence(name="steps", waypoints=waypoints)).ok
    for z in (10, 20):
        rig.run_until(lambda: rig.controller.telemetry().goal is not None
                      and rig.controller.telemetry().goal[2] == pytest.approx(z, abs=1e-9))
        assert rig.controller.telemetry().sequence.index == z // 10
