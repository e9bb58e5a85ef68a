"""The loop (found from outside, a review of the CAN link): an E-stop that could not be sent is tried again the next cycle, a counter from before enabling is no lag, enable is
refused on a bus-off link with what to check."""

from __future__ import annotations

from dataclasses import replace

from hexactl.control.hardware import ActuatorFeedback, ActuatorState, BusState, FeedbackSnapshot, LinkHealth
from hexactl.control.supervisor import Supervisor
from tests.control.test_supervisor import CONFIG, HEALTHY, HELD, MS, PERIOD_S


def test_an_estop_that_could_not_be_sent_is_sent_the_next_cycle(rig):
    """Finding 6: not 100 ms later, and the repeat interval runs from the one that went out."""
    rig.enabled()
    rig.actuators.fail_sends = True  # the transmit queue refuses frames for one cycle
    rig.controller.estop()
    rig.run()
    assert rig.controller.snapshot.state.value == "estop" and rig.actuators.estops == 0
    rig.actuators.fail_sends = False
    rig.run()
    assert rig.actuators.estops == 1
    rig.run(round(0.1 * 1e9 / rig.period_ns) - 1)
    assert rig.actuators.estops == 1
    rig.run()
    assert rig.actuators.estops == 2


def test_a_failed_estop_is_due_at_once_even_within_the_repeat_interval():
    supervisor = Supervisor(CONFIG, PERIOD_S, 0.8)
    supervisor.estop_sent(10 * MS)
    supervisor.estop_failed()
    assert supervisor.estop_due(12 * MS)


def six(counter: int, **leg) -> FeedbackSnapshot:
    healthy = ActuatorFeedback(100.0, 0.0, ActuatorState.ENABLED, 0, (), 0.001, counter)
    return FeedbackSnapshot(tuple(replace(healthy, **leg.get(f"leg{n}", {})) for n in range(1, 7)), 0)


def test_a_counter_from_before_enabling_lags_only_as_long_as_the_session():
    """Finding 2: a rebooted actuator echoes a counter long past (1024) or none (−1) until its
    first FEEDBACK after ENABLE; that is no lag while the session is younger than the limit."""
    supervisor = Supervisor(CONFIG, PERIOD_S, 0.8)
    supervisor.enabled(1 * MS)
    lag = 5  # setpoint_lag_s / period, cycles
    for counter in range(1095, 1096 + lag):
        supervisor.sent(counter, HELD, True)
        for stale in (1024, -1):
            assert supervisor.faults(six(counter, leg3={"setpoint_counter": stale}), HEALTHY, counter, 2 * MS) == []
    supervisor.sent(1096 + lag, HELD, True)  # the first sent lag + 1 cycles ago, none applied: as lagging as that
    faults = supervisor.faults(six(1096 + lag, leg3={"setpoint_counter": -1}), HEALTHY, 1096 + lag, 3 * MS)
    assert [(fault.code, fault.leg) for fault in faults] == [("setpoints_not_applied", 3)]


def test_enable_on_a_bus_off_link_is_refused_saying_what_to_check(rig):
    """Finding 7: not accepted, then latched link_failed a cycle later."""
    rig.actuators.bus_state = BusState.BUS_OFF
    rig.run(2)
    refused = rig.controller.enable()
    assert not refused.ok and refused.error == "send_failed"
    assert refused.message.startswith("the link reports the CAN bus off: the CAN interface left the bus")
    assert "terminations" in refused.message and rig.controller.snapshot.state.value == "disabled"


def test_the_bus_off_refusal_quotes_the_links_detail():
    from hexactl.control.preconditions import check_enable
    from hexactl.control.snapshot import ControlState

    class View:
        state = ControlState.DISABLED
        feedback = six(0)
        link = LinkHealth(BusState.BUS_OFF, 1, "send 0x02F failed: Network is down")

    refusal = check_enable(View(), 0.05)  # type: ignore[arg-type]
    assert refusal is not None and refusal[1].startswith(
        "the link reports the CAN bus off (send 0x02F failed: Network is down): the CAN interface left the bus")
