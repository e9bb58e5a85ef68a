"""The controller link and six simulated actuators over an in-process ``virtual:`` bus,
stepped in simulated time (tests/can/harness.py)."""

from __future__ import annotations

import pytest

from firmware_proto import codec
from firmware_proto.codec import EStopReason, Fault
from hexactl.adapters.can.link import LinkConfig
from hexactl.control.hardware import ActuatorCommand, ActuatorState, BusState, EstopCause
from tests.can.harness import START_MM, Rig

ALL = [ActuatorState.ENABLED] * 6


@pytest.fixture
def rig():
    rig = Rig()
    yield rig
    rig.close()


def enable(rig: Rig) -> None:
    rig.idle(2)  # the link's bare SYNCs bring feedback: positions known, protocol checked
    assert rig.link.send_command(None, ActuatorCommand.ENABLE)
    rig.hold(2)
    assert [a.state for a in rig.snapshot.actuators] == ALL


def states(rig: Rig) -> list[ActuatorState]:
    return [a.state for a in rig.snapshot.actuators]


def test_positions_are_known_before_enabling(rig):
    assert rig.snapshot.actuators[0].heartbeat_age_s == 0.0
    rig.idle(2)  # the link's bare SYNCs schedule feedback in every state
    assert rig.snapshot.positions_mm == START_MM
    assert states(rig) == [ActuatorState.DISABLED] * 6


def test_enable_and_follow_a_ramp_past_counter_wrap(rig):
    enable(rig)
    start = rig.snapshot.positions_mm
    for k in range(1, 461):  # 0.1 mm per 2 ms = 50 mm/s for 0.8 s, then hold; counters beyond 255
        rig.cycle([p + 0.1 * min(k, 400) for p in start])
    for position, origin in zip(rig.snapshot.positions_mm, start):
        assert position == pytest.approx(origin + 40.0, abs=0.001)
    counters = [a.setpoint_counter for a in rig.snapshot.actuators]
    assert all(rig.counter - 3 <= c <= rig.counter - 1 for c in counters)
    health = rig.link.link_health()
    assert (health.bus_state, health.send_failures, health.detail) == (BusState.ACTIVE, 0, "")
    assert rig.link.stats().undecodable_frames == 0


def test_locked_leg_holds_its_length(rig):
    enable(rig)
    assert rig.link.send_command(3, ActuatorCommand.LOCK)
    rig.hold(2)
    locked = rig.snapshot.positions_mm[2]
    start = rig.snapshot.positions_mm
    for k in range(1, 151):
        rig.cycle([p + 0.2 * min(k, 100) for p in start])
    assert rig.snapshot.positions_mm[2] == locked
    assert rig.snapshot.positions_mm[0] == pytest.approx(start[0] + 20.0, abs=0.001)
    assert states(rig)[2] is ActuatorState.LOCKED
    assert rig.firmwares[2].position_um == locked * 1000  # the true length, not just the report


def test_estop_latches_and_wins(rig):
    enable(rig)
    assert rig.link.send_estop(EstopCause.SAFETY_CHAIN)
    rig.hold(1)
    assert states(rig) == [ActuatorState.ESTOP] * 6
    assert [firmware.last_estop_reason for firmware in rig.firmwares] == [EStopReason.SAFETY_CHAIN] * 6  # logged
    assert all(a.fault_bits & Fault.ESTOP for a in rig.snapshot.actuators)
    held = rig.snapshot.positions_mm
    for _ in range(50):
        rig.cycle([p + 5.0 for p in held])  # set-points and even ENABLE change nothing
    rig.link.send_command(None, ActuatorCommand.ENABLE)
    rig.hold(5)
    assert states(rig) == [ActuatorState.ESTOP] * 6 and rig.snapshot.positions_mm == held
    rig.hold(150)  # 300 ms after the ESTOP frame: now it can be cleared, then enabled
    rig.link.send_command(None, ActuatorCommand.CLEAR_FAULT)
    rig.hold(2)
    assert states(rig) == [ActuatorState.DISABLED] * 6
    assert all(a.fault_bits == 0 for a in rig.snapshot.actuators)
    rig.link.send_command(None, ActuatorCommand.ENABLE)
    rig.hold(2)
    assert states(rig) == ALL


def test_watchdog_trip_latches_until_clear_fault_and_enable(rig):
    enable(rig)
    rig.idle(10)  # the loop stops sending: 20 ms > (5 + ½) · 2 ms
    assert states(rig) == [ActuatorState.FAULT] * 6
    assert all(a.fault_bits == Fault.COMM_TIMEOUT for a in rig.snapshot.actuators)
    assert rig.link.stats().emergencies == (1,) * 6
    rig.hold(20)
    assert states(rig) == [ActuatorState.FAULT] * 6
    rig.link.send_command(None, ActuatorCommand.CLEAR_FAULT)
    rig.hold(2)
    rig.link.send_command(None, ActuatorCommand.ENABLE)
    rig.hold(2)
    assert states(rig) == ALL


def test_heartbeat_loss_is_detected_within_the_configured_time(rig):
    enable(rig)
    rig.firmwares[3].inject.silent = True
    rig.hold(100)  # 200 ms: not yet
    assert rig.link.silent_legs() == ()
    rig.hold(60)  # 320 ms
    assert rig.link.silent_legs() == (4,)
    ages = [a.heartbeat_age_s for a in rig.snapshot.actuators]
    assert ages[3] > LinkConfig().heartbeat_timeout_s and max(ages[:3] + ages[4:]) < 0.01
    assert "silent legs: 4" in rig.link.link_health().detail


def test_lost_command_is_retried(rig):
    rig.hold(2)
    rig.flush()
    rig.firmwares[1].inject.drop_next = 2  # the DISABLE a first command goes behind, and the ENABLE
    rig.link.send_command(2, ActuatorCommand.ENABLE)
    rig.idle(5)
    assert states(rig)[1] is ActuatorState.DISABLED  # lost; the retry is due after 20 ms
    rig.idle(6)
    assert states(rig)[1] is ActuatorState.ENABLED and rig.link.stats().command_timeouts == 0


def test_out_of_stroke_setpoint_faults_the_actuator(rig):
    enable(rig)
    positions = list(rig.snapshot.positions_mm)
    positions[4] = 850.001
    rig.cycle(positions)
    rig.hold(1)
    five = rig.snapshot.actuators[4]
    assert five.state is ActuatorState.FAULT and five.fault_bits == Fault.SETPOINT_RANGE
    assert rig.snapshot.positions_mm[4] == START_MM[4]


def test_injected_corrupt_and_replayed_frames_are_ignored_and_reported(rig):
    enable(rig)
    rig.hold(5)
    hold = rig.snapshot.positions_mm
    rig.spy_frames()
    rig.cycle(hold)
    setpoint_12, _, _, sync = (frame for frame in rig.spy_frames() if frame[0] < 0x080)
    far = codec.encode_setpoints(rig.counter & 0xFF, [round(p * 1000) + 700 for p in hold])
    corrupted = [(can_id, payload[:-1] + bytes((payload[-1] ^ 0x5A,))) for can_id, payload in far]
    for can_id, payload in [*corrupted, setpoint_12, sync]:  # bad CRCs, then a replay of the last cycle
        rig.spy.send(codec_message(can_id, payload))
    rig.hold(60)  # past the next heartbeat
    assert rig.snapshot.positions_mm == hold
    assert states(rig) == ALL
    # Nodes 1, 2: SETPOINT_12 and SYNC, each corrupted and replayed; nodes 3-6: their corrupted
    # SETPOINT frame and both SYNCs.
    assert rig.link.stats().rejected_frames == (4, 4, 3, 3, 3, 3)
    # The link hears the injected frames too: counted, never acted on.
    assert (rig.link.stats().undecodable_frames, rig.link.stats().foreign_frames) == (4, 2)


def codec_message(can_id: int, payload: bytes):
    import can

    return can.Message(arbitration_id=can_id, data=payload, is_extended_id=False)


@pytest.mark.parametrize("leg", [1, 4])
def test_the_first_enable_is_carried_out_whatever_sequence_the_actuator_executed_last(rig, leg):
    """An actuator outlives a controller's restart: its last executed command's sequence is
    the one the new link starts at (one in 256). It took the first ENABLE for a retry of
    that command, acknowledged it and stayed disabled. Now the first command goes behind a
    DISABLE that changes nothing at rest, and carries the next sequence."""
    rig.idle(2)
    start = rig.link._nodes[leg - 1].sequence
    rig.firmwares[leg - 1]._last_command = (start, codec.CommandResult.ACCEPTED)  # the last session's DISABLE
    assert rig.link.send_command(None, ActuatorCommand.ENABLE)
    rig.hold(2)
    assert states(rig) == ALL
    # Only the first command: the next one has no DISABLE before it.
    rig.spy_frames()  # those so far
    assert rig.link.send_command(None, ActuatorCommand.DISABLE)
    rig.hold(2)
    frames = rig.spy_frames()
    commands = [codec.decode(can_id, payload) for can_id, payload in frames if 0x101 <= can_id <= 0x106]
    assert [command.command for command in commands] == [codec.CommandCode.DISABLE] * 6
    assert states(rig) == [ActuatorState.DISABLED] * 6
