"""Supervision: FAULT and ESTOP are latched, the platform holds, reset returns to DISABLED."""

import numpy as np
import pytest

from hexactl.control.hardware import ActuatorCommand, ActuatorState, BusState


def _until_state(rig, state, seconds=1.0):
    return rig.run_until(lambda: rig.controller.snapshot.state.value == state, limit=int(seconds * 1e9 / rig.period_ns))


def test_lost_heartbeat_faults_holds_and_stays_latched_until_reset(rig):
    rig.enabled()
    assert rig.controller.move([200, 0, 0, 0, 0, 0]).ok
    rig.run(300)
    rig.actuators.silence(3)
    cycles = _until_state(rig, "fault")
    timeout = rig.controller.config.supervision.heartbeat_timeout_s
    assert cycles * rig.period_ns / 1e9 == pytest.approx(timeout, abs=2 * rig.period_ns / 1e9)
    fault = rig.controller.snapshot.faults[0]
    assert (fault.code, fault.leg) == ("heartbeat_lost", 3)
    held = rig.sent[-1].copy()
    sent = len(rig.sent)
    rig.run(100)
    assert len(rig.sent) == sent + 100  # keeps sending …
    assert np.all(rig.sent[sent:] == held)  # … the held set-points
    rig.actuators.silence(3, False)
    rig.run(100)
    assert rig.controller.snapshot.state.value == "fault"  # latched
    assert rig.controller.move([0, 0, 0, 0, 0, 0]).error == "latched"
    assert rig.controller.enable().error == "latched"
    assert rig.controller.reset().ok
    rig.run(2)
    assert rig.controller.snapshot.state.value == "disabled" and rig.controller.snapshot.faults == ()
    assert rig.actuators.commands[-2:] == [(None, ActuatorCommand.DISABLE), (None, ActuatorCommand.CLEAR_FAULT)]
    sent = len(rig.sent)
    rig.run(50)
    assert len(rig.sent) == sent  # DISABLED sends nothing
    rig.enabled()  # and starts again from where the platform stands
    assert rig.sent[-1] == pytest.approx(held, abs=0.5)
    rig.assert_setpoints_safe()


@pytest.mark.parametrize(("inject", "code"), [
    (lambda a: a.inject_fault(2, 0x10), "actuator_fault"),
    (lambda a: setattr(a, "bus_state", BusState.BUS_OFF), "link_failed"),
    (lambda a: setattr(a, "fail_sends", True), "send_failed"),
])
def test_actuator_and_link_failures_fault(rig, inject, code):
    rig.enabled()
    rig.run(10)
    inject(rig.actuators)
    _until_state(rig, "fault", seconds=0.1)
    assert code in {f.code for f in rig.controller.snapshot.faults}


def test_an_actuator_fault_is_named_in_the_fault_and_the_telemetry(rig):
    rig.enabled()
    rig.run(10)
    rig.actuators.inject_fault(2, 0x20 | 0x80 | 1 << 13)  # OVERCURRENT, SENSOR and a bit the protocol does not define
    _until_state(rig, "fault", seconds=0.1)
    fault = rig.controller.snapshot.faults[0]
    assert (fault.code, fault.leg, fault.message) == (
        "actuator_fault", 2, "leg 2 reports FAULT, faults: overcurrent, sensor, bit_13 (0x20a0)")
    leg = rig.controller.telemetry().legs[1]
    assert (leg.state, leg.fault_bits, leg.fault_names) == ("fault", 0x20A0, ("overcurrent", "sensor", "bit_13"))
    assert rig.controller.telemetry().legs[0].fault_names == ()


def test_setpoints_that_are_not_applied_fault(rig):
    rig.enabled()
    rig.run(10)
    rig.actuators.applied_counter = _Frozen(rig.actuators.applied_counter)
    cycles = _until_state(rig, "fault")
    assert rig.controller.snapshot.faults[0].code == "setpoints_not_applied"
    assert cycles * rig.period_ns / 1e9 == pytest.approx(rig.controller.config.supervision.setpoint_lag_s,
                                                         abs=3 * rig.period_ns / 1e9)


class _Frozen(list):
    """A counter list the actuators can no longer update."""

    def __setitem__(self, index, value):
        pass


def test_estop_is_sent_at_once_latched_repeated_and_reset(rig):
    rig.enabled()
    assert rig.controller.move([300, 0, 0, 0, 0, 0]).ok
    rig.run(200)
    result = rig.controller.estop()
    assert result.ok and rig.actuators.estops == 1  # sent from the caller's thread already
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    sent = len(rig.sent)
    rig.run(int(0.35e9 / rig.period_ns))
    assert len(rig.sent) == sent  # no set-points while ESTOP
    assert rig.actuators.estops == 2 + 3  # the loop's on entry, then every 0.1 s
    assert rig.controller.move([0] * 6).error == "latched"
    assert rig.controller.reset().ok
    rig.run(2)
    assert rig.controller.snapshot.state.value == "disabled"
    rig.run(300)
    assert rig.controller.snapshot.state.value == "disabled"  # the actuators left ESTOP: not re-latched
    rig.enabled()


def test_reset_waits_for_the_actuators_estop_hold_off_before_clearing(rig):
    """Actuators refuse CLEAR_FAULT until no E-stop for 250 ms; the loop re-sends E-stops
    every 0.1 s while latched, so an immediate CLEAR_FAULT would always be refused."""
    rig.enabled()
    assert rig.controller.estop().ok
    rig.run(int(0.35e9 / rig.period_ns))
    estops = rig.actuators.estops
    assert rig.controller.reset().ok
    rig.run(2)
    assert (None, "clear_fault") not in rig.actuators.commands  # not yet: the hold-off runs
    hold_off = rig.controller.config.supervision.estop_clear_holdoff_s
    rig.run(int(hold_off * 1e9 / rig.period_ns) + 2)
    assert rig.actuators.commands[-1] == (None, "clear_fault")
    assert rig.actuators.estops == estops  # no E-stop after the reset
    assert set(rig.actuators.states) == {ActuatorState.DISABLED}
    rig.run(300)
    assert rig.controller.snapshot.state.value == "disabled"
    rig.enabled()


def test_enable_that_the_link_cannot_send_is_refused_and_undone(rig):
    rig.run()
    real_send = rig.actuators.send_command

    def refuse_enable_to_leg_3(leg, command):
        if command == "enable":
            rig.actuators.commands.append((leg, command))
            return False  # as the CAN link before leg 3's first heartbeat
        return real_send(leg, command)

    rig.actuators.send_command = refuse_enable_to_leg_3
    rig.controller.enable()
    rig.run(2)
    assert rig.controller.outcome(1).error == "send_failed"
    assert rig.actuators.commands[-2:] == [(None, "enable"), (None, "disable")]
    assert rig.controller.snapshot.state.value == "disabled"


def test_the_hardware_estop_chain_latches_estop_in_any_state(rig):
    rig.actuators.press_estop()
    rig.run()
    assert rig.controller.snapshot.state.value == "estop"
    assert rig.controller.snapshot.faults[-1].code == "estop"


def test_a_fault_during_a_sequence_ends_it(rig):
    rig.enabled()
    assert rig.controller.play("compound").ok
    rig.run(600)
    rig.actuators.inject_fault(6)
    _until_state(rig, "fault", seconds=0.1)
    assert rig.controller.sequence_records().status == "fault"
    assert rig.controller.telemetry().sequence is None


def test_enable_just_after_a_reset_from_an_estop_says_to_wait_a_moment(rig):
    rig.enabled()
    assert rig.controller.estop().ok
    rig.run(5)
    assert rig.controller.reset().ok
    rig.run(1)
    held = rig.controller.enable()
    assert held.error == "actuator_fault" and ": ESTOP" in held.message and "enable again shortly" in held.message
    rig.run_until(lambda: rig.controller.enable().ok, limit=2000)


def test_enable_refusals(make_rig, geometry):
    rig = make_rig()
    rig.actuators.silence(1)
    rig.run(100)
    assert rig.controller.enable().error == "heartbeat_missing"
    rig.actuators.silence(1, False)
    rig.actuators.inject_fault(4)
    rig.run()
    faulted = rig.controller.enable()
    assert (faulted.error, faulted.message) == ("actuator_fault", "leg 4: FAULT, faults: comm_timeout (0x1)")
    rig.actuators.states[3] = rig.actuators.states[0]
    rig.actuators.fault_bits[3] = 0
    original = rig.actuators.positions[0]
    for outside in (geometry.limits.stroke[1] + 5.0, geometry.limits.stroke[0] - 5.0):
        rig.actuators.positions[0] = outside
        rig.run()
        assert rig.controller.enable().error == "outside_stroke"
    rig.actuators.positions[0] = geometry.limits.stroke[1]  # in the stroke, but no pose has these lengths
    rig.run()
    assert rig.controller.enable().error == "pose_unknown"
    rig.actuators.positions[0] = float("nan")  # heard from, but no position reported yet
    rig.run()
    assert rig.controller.enable().error == "heartbeat_missing"
    rig.actuators.positions[0] = original
    rig.run()
    assert rig.controller.enable().ok
    rig.run()
    again = rig.controller.enable()  # the state asked for, as a second disable
    assert (again.ok, again.message) == (True, "already enabled: nothing to do")
    assert rig.controller.reset().error == "not_latched"


def test_two_enables_queued_together_both_succeed_and_enable_once(rig) -> None:
    """A retried enable (its first verdict late, loop_timeout) meets the loop already enabled
    by the first: the state asked for, not a refusal the retrying client must know of."""
    rig.run()
    first, second = rig.controller.enable(), rig.controller.enable()  # both queued before the loop runs
    rig.run()
    assert all(rig.controller.outcome(result.details["ticket"]).ok for result in (first, second))
    assert rig.controller.snapshot.state.value == "enabled"
    assert [command for command in rig.actuators.commands if command[1] is ActuatorCommand.ENABLE] == \
        [(None, ActuatorCommand.ENABLE)]


def test_enable_refused_for_a_silent_leg_says_what_the_link_knows(rig):
    # Bringing up a bus (interface down, wrong bit rate, actuators unpowered): the legs fall
    # silent because of the bus, which only the link can say.
    rig.actuators.silence(1)
    rig.actuators.bus_state = BusState.PASSIVE
    rig.run(100)
    refused = rig.controller.enable()
    assert refused.error == "heartbeat_missing"
    assert refused.message.startswith("leg 1: no report for ") and refused.message.endswith(" s (link: bus passive)")
    rig.actuators.bus_state = BusState.ACTIVE
    rig.run()
    assert rig.controller.enable().message.endswith(" s")  # a healthy link has nothing to add


def test_enable_refused_by_the_loop_when_the_state_changed_meanwhile(rig):
    assert rig.controller.enable().ok  # checked against the last snapshot …
    rig.actuators.silence(2)
    rig.clock.advance(int(0.2e9))  # … but leg 2 falls silent before the loop gets to it
    rig.run()
    verdict = rig.controller.outcome(1)
    assert not verdict.ok and verdict.error == "heartbeat_missing"
    assert rig.controller.snapshot.state.value == "disabled"
    assert any(e.code == "command_refused" for e in rig.controller.events().events)


def test_disable_at_rest_only(rig):
    rig.enabled()
    assert rig.controller.move([100, 0, 0, 0, 0, 0]).ok
    rig.run(10)
    assert rig.controller.disable().error == "busy"
    rig.settle()
    assert rig.controller.disable().ok
    rig.run()
    assert rig.controller.snapshot.state.value == "disabled"
    assert rig.actuators.commands[-1] == (None, ActuatorCommand.DISABLE)
    # Found from outside: it said "enable first", then was refused "already disabled" (exit 1:
    # `hexactl disable && …` failed on a platform already safe). The state asked for is ok.
    again = rig.controller.disable()
    assert again.ok and again.message == "already disabled: nothing to do"
    rig.run()
    assert rig.actuators.commands[-1] == (None, ActuatorCommand.DISABLE) and rig.controller.snapshot.state.value == "disabled"
