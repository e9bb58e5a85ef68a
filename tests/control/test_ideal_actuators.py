from hexactl.control.hardware import ActuatorCommand, ActuatorInterface, ActuatorState, BusState
from hexactl.sim.ideal_actuators import IdealActuators
from tests.firmware_proto.frames import dbc_fault_names

MS = 1_000_000


def test_follows_when_enabled_holds_when_locked_or_disabled(clock):
    actuators = IdealActuators([100.0] * 6, lag_s=0.005, clock_ns=clock)
    assert isinstance(actuators, ActuatorInterface)
    actuators.send_setpoints(0, [200.0] * 6)  # disabled: ignored
    clock.advance(100 * MS)
    assert actuators.read_feedback().positions_mm == (100.0,) * 6
    actuators.send_command(None, ActuatorCommand.ENABLE)
    actuators.send_command(2, ActuatorCommand.LOCK)
    actuators.send_setpoints(1, [200.0] * 6)
    clock.advance(100 * MS)
    feedback = actuators.read_feedback()
    assert feedback.actuators[1].position_mm == 100.0 and feedback.actuators[1].state is ActuatorState.LOCKED
    assert abs(feedback.actuators[0].position_mm - 200.0) < 1e-6
    assert feedback.actuators[0].setpoint_counter == 1 and feedback.actuators[1].setpoint_counter == -1
    assert feedback.actuators[0].heartbeat_age_s == 0.0


def test_faults_heartbeats_and_estop(clock):
    actuators = IdealActuators([100.0] * 6, clock_ns=clock)
    actuators.silence(3)
    clock.advance(50 * MS)
    assert actuators.read_feedback().actuators[2].heartbeat_age_s == 0.05
    actuators.inject_fault(1, 0x4)
    feedback = actuators.read_feedback().actuators[0]
    assert (feedback.state, feedback.fault_bits, feedback.fault_names) == (ActuatorState.FAULT, 0x4, ("setpoint_range",))
    actuators.send_command(None, ActuatorCommand.CLEAR_FAULT)
    assert actuators.read_feedback().actuators[0].state is ActuatorState.DISABLED
    actuators.bus_state = BusState.BUS_OFF
    assert not actuators.send_setpoints(0, [0.0] * 6)
    assert actuators.link_health().send_failures == 1
    actuators.bus_state = BusState.ACTIVE
    assert actuators.send_estop()
    assert {a.state for a in actuators.read_feedback().actuators} == {ActuatorState.ESTOP}


def test_injected_fault_bits_are_named_as_the_dbc_names_them_and_unknown_ones_by_number(clock):
    actuators = IdealActuators([100.0] * 6, clock_ns=clock)
    for bit, name in dbc_fault_names().items():
        actuators.inject_fault(2, 1 << bit)
        assert actuators.read_feedback().actuators[1].fault_names == (name.lower(),), name
    actuators.inject_fault(2, 1 << 13 | 0x81)
    assert actuators.read_feedback().actuators[1].fault_names == ("comm_timeout", "sensor", "bit_13")
    actuators.fault_bits[1] = 0  # what the names follow
    assert actuators.read_feedback().actuators[1].fault_names == ()
