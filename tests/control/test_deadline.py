"""Commands that die with their sender: the loop refuses a command whose ``deadline_ns``
has passed at the cycle that reaches it (``expired``), before its handler runs; one in
time is carried out. The facade puts the deadline on what it submits. And planning is
bounded: no duration, dwell or speed makes it overflow or sample without end."""

from __future__ import annotations

import pytest

from hexactl.control.planning import MAX_DWELL_S, MAX_MOTION_S

POSE = [50, 0, 0, 0, 0, 0]


def verdict(rig, result):
    assert result.ok and result.details["pending"], result
    rig.run()
    return rig.controller.outcome(result.details["ticket"])


@pytest.mark.parametrize("method, arguments", [("move", (POSE,)), ("play", ("x_sweep",)), ("leg_lock", (2,))])
def test_a_command_reaching_the_loop_after_its_deadline_is_refused_expired(rig, method, arguments):
    rig.enabled()
    # The next cycle runs one period from now: a deadline half a period ahead has passed by then.
    deadline_ns = rig.clock.now_ns + rig.period_ns // 2
    outcome = verdict(rig, getattr(rig.controller, method)(*arguments, deadline_ns=deadline_ns))
    assert not outcome.ok and outcome.error == "expired" and "not carried out" in outcome.message
    snapshot = rig.controller.snapshot
    assert snapshot.motion.value == "holding" and snapshot.sequence is None and snapshot.lock is None
    assert rig.controller.events().events[-1].code == "command_refused"
    rig.run(50)
    assert rig.controller.telemetry().pose_command == pytest.approx((0,) * 6, abs=1e-9)  # nothing ran later


def test_a_command_reaching_the_loop_by_its_deadline_is_carried_out(rig):
    rig.enabled()
    deadline_ns = rig.clock.now_ns + rig.period_ns  # exactly the next cycle's time: still in time
    outcome = verdict(rig, rig.controller.move(POSE, deadline_ns=deadline_ns))
    assert outcome.ok
    rig.settle()
    assert rig.controller.telemetry().pose_command == pytest.approx(POSE, abs=1e-9)


def test_enable_and_resume_carry_the_deadline_too(rig):
    deadline_ns = rig.clock.now_ns + rig.period_ns // 2
    outcome = verdict(rig, rig.controller.enable(deadline_ns=deadline_ns))
    assert outcome.error == "expired" and rig.controller.snapshot.state.value == "disabled"
    rig.enabled()
    assert verdict(rig, rig.controller.play("x_sweep")).ok
    assert verdict(rig, rig.controller.pause()).ok
    rig.run_until(lambda: rig.controller.snapshot.sequence.phase.value == "paused")
    outcome = verdict(rig, rig.controller.resume(deadline_ns=rig.clock.now_ns + rig.period_ns // 2))
    assert outcome.error == "expired" and rig.controller.snapshot.sequence.phase.value == "paused"


def test_planning_refuses_unbounded_durations_dwells_and_speeds(rig):
    rig.enabled()
    controller = rig.controller
    for duration in (1e200, MAX_MOTION_S * 1.01):
        result = controller.validate_pose(POSE, duration)
        assert result.error == "invalid_argument" and f"up to {MAX_MOTION_S:g}" in result.message, result
    result = controller.validate_pose(POSE, speed=1e-4)  # some 2500 s: refused before sampling 1.2 million cycles
    assert result.error == "planning_failed" and f"at most {MAX_MOTION_S:g} s" in result.message, result
    from hexactl.control.planning import Waypoint, plan_path

    plan = plan_path(controller._context(controller.snapshot), controller.snapshot.trajectory,
                     [Waypoint(POSE, dwell_s=MAX_DWELL_S * 2)])
    assert plan.refusal is not None and f"0 to {MAX_DWELL_S:g} s" in plan.refusal.message
    # The limit is on the plan's motion together: 3 moves of 250 s exceed 600 s.
    plan = plan_path(controller._context(controller.snapshot), controller.snapshot.trajectory,
                     [Waypoint(POSE, 250.0), Waypoint((0,) * 6, 250.0), Waypoint(POSE, 250.0)])
    assert plan.refusal is not None and "waypoint 3" in plan.refusal.message and "at most 600 s" in plan.refusal.message
    assert "after 500 s of the moves before it" in plan.refusal.message and "split the sequence" in plan.refusal.message
    # it said 248.9 s, the stretch's first attempt, for a move asked to take 250 s at least
    assert "the move would take 250 s, after 500 s" in plan.refusal.message, plan.refusal.message
    assert "moves before it" not in result.message  # a single move has none
