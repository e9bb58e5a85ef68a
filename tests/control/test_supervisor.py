"""The supervisor alone: what it declares a fault while ENABLED, the actuators' E-stop
and its grace after a reset, and the E-stop's timing (repeat, CLEAR_FAULT hold-off)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from hexactl.control.config import SupervisionConfig
from hexactl.control.hardware import ActuatorFeedback, ActuatorState, BusState, FeedbackSnapshot, LinkHealth
from hexactl.control.supervisor import Supervisor

PERIOD_S = 0.002
CONFIG = SupervisionConfig(heartbeat_timeout_s=0.05, state_timeout_s=0.5, setpoint_lag_s=0.01, max_send_failures=3,
                           estop_repeat_s=0.1, estop_clear_holdoff_s=0.3)
MS = 1_000_000
HEALTHY = LinkHealth(BusState.ACTIVE, 0)
MAX_STEP_MM = 0.8  # a leg's speed limit × PERIOD_S: 400 mm/s
HELD = (100.0,) * 6
"""Set-points where :func:`feedback`'s actuators stand."""


def feedback(state=ActuatorState.ENABLED, counter=100, **leg) -> FeedbackSnapshot:
    """Six actuators in ``state`` that applied set-point ``counter``; ``leg`` ({leg_n: changes}) alters some."""
    healthy = ActuatorFeedback(100.0, 0.0, state, 0, (), 0.001, counter)
    return FeedbackSnapshot(tuple(replace(healthy, **leg.get(f"leg{n}", {})) for n in range(1, 7)), 0)


@pytest.fixture
def supervisor() -> Supervisor:
    supervisor = Supervisor(CONFIG, PERIOD_S, MAX_STEP_MM)
    supervisor.enabled(0)
    return supervisor


def codes(faults) -> list[tuple[str, int | None]]:
    return [(f.code, f.leg) for f in faults]


def test_healthy_actuators_that_reached_their_state_give_no_fault(supervisor):
    assert supervisor.faults(feedback(), HEALTHY, 100, 1 * MS) == []


def test_each_fault_is_named_with_its_leg(supervisor):
    bad = feedback(leg2={"heartbeat_age_s": 0.06}, leg4={"fault_bits": 0x9, "fault_names": ("comm_timeout", "sensor")},
                   leg5={"state": ActuatorState.FAULT})
    faults = supervisor.faults(bad, HEALTHY, 100, 1 * MS)
    assert codes(faults) == [("heartbeat_lost", 2), ("actuator_fault", 4), ("actuator_fault", 5)]
    assert [f.message for f in faults[1:]] == ["leg 4 reports ENABLED, faults: comm_timeout, sensor (0x9)",
                                               "leg 5 reports FAULT, faults: none"]
    assert faults[0].message == "leg 2: no report for 0.060 s"
    never_heard = feedback(leg1={"heartbeat_age_s": float("inf")})
    assert codes(supervisor.faults(never_heard, HEALTHY, 100, 1 * MS)) == [("heartbeat_lost", 1)]


def test_a_leg_not_heard_in_this_protocol_says_what_the_link_says_not_inf_seconds(supervisor):
    """An actuator that restarts, while enabled, into a firmware of another protocol version
    is not heard by the link (its age is infinite): "no report for inf s" said nothing."""
    link = LinkHealth(BusState.ACTIVE, 0, "silent legs: 2; leg 1 speaks protocol version 2, this controller 1: it is "
                      "not enabled while it does; leg 12 restarted (…)")  # the other legs' notes are not this fault's
    [fault] = supervisor.faults(feedback(leg1={"heartbeat_age_s": float("inf")}), link, 100, 1 * MS)
    assert fault.message == ("leg 1: not heard in this controller's protocol: leg 1 speaks "
                             "protocol version 2, this controller 1: it is not enabled while it does"), fault.message
    [fault] = supervisor.faults(feedback(leg1={"heartbeat_age_s": float("inf")}), None, 100, 1 * MS)
    assert fault.message == "leg 1: not heard in this controller's protocol"


def test_a_leg_has_the_state_timeout_to_reach_its_state_then_none(supervisor):
    late = feedback(leg3={"state": ActuatorState.DISABLED})
    assert supervisor.faults(late, HEALTHY, 100, 499 * MS) == []
    assert codes(supervisor.faults(late, HEALTHY, 100, 500 * MS)) == [("actuator_state", 3)]
    # Once there, leaving the state is a fault at once, however early.
    supervisor.enabled(1000 * MS)
    assert supervisor.faults(feedback(), HEALTHY, 100, 1001 * MS) == []
    assert codes(supervisor.faults(late, HEALTHY, 100, 1002 * MS)) == [("actuator_state", 3)]


def test_a_leg_that_left_its_state_because_it_restarted_says_so(supervisor):
    """A restarted actuator reads DISABLED with no fault: the fault says it restarted."""
    supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)  # all arrived in ENABLED
    restarted = feedback(leg4={"state": ActuatorState.DISABLED, "restarts": 1})
    (fault,) = supervisor.faults(restarted, HEALTHY, 100, 2 * MS)
    assert fault.message == ("leg 4 is DISABLED, expected ENABLED; it has restarted 1 time(s) since the link opened "
                             "(a power or watchdog reset): check its supply and wiring")
    (fault,) = supervisor.faults(feedback(leg4={"state": ActuatorState.DISABLED}), HEALTHY, 100, 3 * MS)
    assert fault.message == "leg 4 is DISABLED, expected ENABLED"


def test_a_locked_leg_is_expected_locked_and_not_to_follow_setpoints(supervisor):
    supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)  # all arrived in ENABLED
    supervisor.expect(2, ActuatorState.LOCKED, 10 * MS)
    locked = feedback(counter=100, leg2={"state": ActuatorState.LOCKED, "setpoint_counter": 3})
    assert supervisor.faults(locked, HEALTHY, 100, 11 * MS) == []  # arrives
    assert supervisor.faults(locked, HEALTHY, 100, 12 * MS) == []  # its stale counter does not count
    assert codes(supervisor.faults(feedback(), HEALTHY, 100, 13 * MS)) == [("actuator_state", 2)]


@pytest.mark.parametrize("max_step_mm", [MAX_STEP_MM, 0.05])
def test_a_locked_leg_away_from_its_locked_reading_for_the_time_allowed_has_slipped(max_step_mm):
    """Compared with the set-point it is sent (its locked reading); the limit is
    ``locked_slip_mm``, or a cycle's step of the leg when that is less: the actuator checks
    the first set-point after UNLOCK from where it measures."""
    supervisor = Supervisor(CONFIG, PERIOD_S, max_step_mm)
    supervisor.enabled(0)
    supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)
    supervisor.expect(2, ActuatorState.LOCKED, 2 * MS)
    supervisor.sent(100, HELD, True)
    limit, hold_ms = min(CONFIG.locked_slip_mm, max_step_mm), round(CONFIG.following_error_s * 1000)

    def locked(position_mm: float) -> FeedbackSnapshot:
        return feedback(leg2={"state": ActuatorState.LOCKED, "position_mm": position_mm})

    assert supervisor.faults(locked(100.0), HEALTHY, 100, 3 * MS) == []  # arrived in LOCKED
    assert supervisor.faults(locked(100.0 + 0.99 * limit), HEALTHY, 100, 4 * MS) == []
    assert supervisor.faults(locked(100.0 + 0.99 * limit), HEALTHY, 100, (4 + 2 * hold_ms) * MS) == []
    crept = locked(100.0 - 1.01 * limit)
    assert supervisor.faults(crept, HEALTHY, 100, 500 * MS) == []  # over the limit from now
    (fault,) = supervisor.faults(crept, HEALTHY, 100, (500 + hold_ms) * MS)
    assert (fault.code, fault.leg) == ("locked_leg_slipped", 2)
    assert fault.message == (f"leg 2 is {(100.0 - 1.01 * limit) - 100.0:+.3f} mm from where it was locked for {hold_ms / 1000:.3f} s "
                             f"(limit {limit:g} mm): its brake slips or the leg is overloaded; check the leg before "
                             "reset and enable")
    # unlocked, the leg is an enabled one again: the following error's limit, timed afresh
    supervisor.expect(2, ActuatorState.ENABLED, 600 * MS)
    assert supervisor.faults(feedback(leg2={"position_mm": 100.0 - 1.01 * limit}), HEALTHY, 100, 601 * MS) == []
    assert supervisor.faults(feedback(leg2={"position_mm": 100.0 - 1.01 * limit}), HEALTHY, 100, 900 * MS) == []


def test_setpoints_not_applied_for_longer_than_the_lag_is_a_fault(supervisor):
    supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)  # arrived: from now on the counters count
    lag = 5  # setpoint_lag_s / period, cycles
    assert supervisor.faults(feedback(counter=100), HEALTHY, 100 + lag, 2 * MS) == []
    assert codes(supervisor.faults(feedback(counter=100), HEALTHY, 101 + lag, 3 * MS)) == [
        ("setpoints_not_applied", leg) for leg in range(1, 7)]


def test_a_leg_away_from_the_setpoint_it_applied_for_the_time_allowed_is_a_following_error(supervisor):
    """Compared with the set-point of the counter the leg reports applied: a leg that is
    where an older set-point put it (late frames, a slow host) is not in error."""
    supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)  # arrived
    limit, hold_ms = CONFIG.following_error_mm, round(CONFIG.following_error_s * 1000)
    for counter in (100, 101, 102):  # leg 1 moves on 20 mm a cycle, the others hold
        supervisor.sent(counter, (100.0 + 20.0 * (counter - 100),) + HELD[1:], True)
    assert supervisor.faults(feedback(counter=100), HEALTHY, 102, 2 * MS) == []  # where counter 100 put them
    stuck = feedback(counter=102, leg3={"position_mm": 100.0 - 1.01 * limit})  # leg 1 40 mm behind, leg 3 just over
    assert supervisor.faults(stuck, HEALTHY, 102, 10 * MS) == []  # over the limit from now
    assert supervisor.faults(stuck, HEALTHY, 102, (10 + hold_ms - 1) * MS) == []
    faults = supervisor.faults(stuck, HEALTHY, 102, (10 + hold_ms) * MS)
    assert codes(faults) == [("following_error", 1), ("following_error", 3)]
    assert faults[0].message.startswith(f"leg 1 is -40.000 mm from its set-point for {hold_ms / 1000:.3f} s "
                                        f"(limit {limit:g} mm): jammed")
    # Back within the limit, the time starts again; so does it on enable.
    assert supervisor.faults(feedback(counter=102, leg1={"position_mm": 140.0}), HEALTHY, 102, 200 * MS) == []
    assert supervisor.faults(stuck, HEALTHY, 102, 201 * MS) == []
    assert codes(supervisor.faults(stuck, HEALTHY, 102, (201 + hold_ms) * MS)) == [("following_error", 1),
                                                                                   ("following_error", 3)]
    supervisor.enabled(400 * MS)
    supervisor.faults(stuck, HEALTHY, 102, 401 * MS)  # arrived in ENABLED
    assert supervisor.faults(stuck, HEALTHY, 102, 402 * MS) == []
    assert supervisor.faults(stuck, HEALTHY, 102, (402 + hold_ms - 1) * MS) == []


@pytest.mark.parametrize("state,failed", [(BusState.ACTIVE, False), (BusState.WARNING, False),
                                          (BusState.PASSIVE, False), (BusState.BUS_OFF, True), (BusState.DOWN, True)])
def test_only_a_bus_that_sends_nothing_fails_the_link(supervisor, state, failed):
    faults = supervisor.faults(feedback(), LinkHealth(state, 0, "driver says so"), 100, 1 * MS)
    assert codes(faults) == ([("link_failed", None)] if failed else [])
    if failed:
        assert faults[0].message == f"bus {state.value}: driver says so"


def test_send_failures_in_a_row_fault_and_a_success_ends_the_run(supervisor):
    for _ in range(2):
        supervisor.sent(100, HELD, False)
    assert supervisor.faults(feedback(), HEALTHY, 100, 1 * MS) == []
    supervisor.sent(100, HELD, True)
    for _ in range(2):
        supervisor.sent(100, HELD, False)
    assert supervisor.faults(feedback(), HEALTHY, 100, 1 * MS) == []
    supervisor.sent(100, HELD, False)
    assert codes(supervisor.faults(feedback(), HEALTHY, 100, 1 * MS)) == [("send_failed", None)]
    supervisor.enabled(2 * MS)  # enabling starts afresh
    assert supervisor.faults(feedback(), HEALTHY, 100, 3 * MS) == []


def test_an_actuator_estop_is_reported_except_in_a_resets_grace(supervisor):
    estop = feedback(leg6={"state": ActuatorState.ESTOP})
    assert not supervisor.estop_reported(feedback(), 0)
    assert supervisor.estop_reported(estop, 0)
    supervisor.reset(1000 * MS)  # no E-stop sent by the loop: CLEAR_FAULT at once, grace the state timeout
    assert not supervisor.estop_reported(estop, 1499 * MS)
    assert supervisor.estop_reported(estop, 1500 * MS)


def test_the_estop_repeats_while_latched(supervisor):
    supervisor.estop_sent(10 * MS)
    assert not supervisor.estop_due(109 * MS)
    assert supervisor.estop_due(110 * MS)
    supervisor.estop_sent(110 * MS)
    assert not supervisor.estop_due(209 * MS)


def test_clear_fault_waits_for_the_holdoff_after_the_last_estop_and_is_sent_once(supervisor):
    supervisor.estop_sent(100 * MS)
    supervisor.reset(200 * MS)
    assert not supervisor.clear_fault_due(None, 399 * MS)
    assert supervisor.clear_fault_due(None, 400 * MS)
    assert not supervisor.clear_fault_due(None, 401 * MS)
    assert not supervisor.clear_fault_due(feedback(state=ActuatorState.DISABLED), 500 * MS)  # all left E-stop
    # the grace runs from the CLEAR_FAULT, not from the reset
    estop = feedback(leg1={"state": ActuatorState.ESTOP})
    assert not supervisor.estop_reported(estop, 899 * MS)
    assert supervisor.estop_reported(estop, 900 * MS)


def test_a_reset_without_estops_clears_at_once_and_a_new_estop_cancels_it(supervisor):
    supervisor.reset(50 * MS)
    assert supervisor.clear_fault_due(None, 50 * MS)
    supervisor.reset(60 * MS)
    supervisor.latched_estop()
    assert not supervisor.clear_fault_due(None, 10_000 * MS)


def test_clear_fault_is_repeated_in_the_grace_while_an_actuator_still_reports_estop(supervisor):
    """One actuator got the loop's last E-stops late and refused the first CLEAR_FAULT
    within its own hold-off: the reset repeats it, then stops once none reports E-stop."""
    supervisor.estop_sent(100 * MS)
    supervisor.reset(200 * MS)
    late = feedback(state=ActuatorState.DISABLED, leg4={"state": ActuatorState.ESTOP})
    assert supervisor.clear_fault_due(late, 400 * MS)
    assert not supervisor.clear_fault_due(late, 499 * MS)
    assert supervisor.clear_fault_due(late, 500 * MS)  # every estop_repeat_s
    assert supervisor.clear_fault_due(late, 600 * MS)
    assert not supervisor.clear_fault_due(feedback(state=ActuatorState.DISABLED), 700 * MS)
    assert not supervisor.clear_fault_due(late, 800 * MS)  # it stopped repeating once all had left


def test_clear_fault_repeats_end_a_repeat_before_the_grace_does(supervisor):
    supervisor.reset(0)  # no E-stop sent: due at once, grace 500 ms
    stuck = feedback(state=ActuatorState.ESTOP)
    sent = [t for t in range(0, 1000, 10) if supervisor.clear_fault_due(stuck, t * MS)]
    assert sent == [0, 100, 200, 300, 400]
    assert supervisor.estop_reported(stuck, 500 * MS)  # still in E-stop after the grace: the loop latches it
