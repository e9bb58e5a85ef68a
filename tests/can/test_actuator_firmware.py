"""The simulated firmware against PROTOCOL.md, driven frame by frame with explicit times."""

from __future__ import annotations

import pytest

from firmware_proto import codec
from firmware_proto.codec import (
    ActuatorState,
    CommandAck,
    CommandCode,
    CommandResult,
    Emergency,
    EStopReason,
    Fault,
    FaultCode,
    Feedback,
    Heartbeat,
    LoopRate,
)
from hexactl.sim.actuator_firmware import ActuatorFirmware, ActuatorParams, FaultInjection

START_UM = 400_000
PARAMS = ActuatorParams(soft_limits_um=(0, 850_000), max_velocity_um_s=400_000.0)
RATE = LoopRate.HZ_500
T = 1 / RATE


def decoded(frames):
    return [codec.decode(can_id, payload) for can_id, payload in frames]


def of_type(frames, kind):
    return [message for message in decoded(frames) if isinstance(message, kind)]


def command(fw, code, sequence, t, loop_rate=LoopRate.NOT_SET, watchdog=0):
    """The command's answers: acknowledgement and emergencies (heartbeats left out)."""
    frames = fw.receive(*codec.encode_command(fw.node, code, sequence, loop_rate, watchdog), t)
    return [message for message in decoded(frames) if not isinstance(message, Heartbeat)]


def enabled(node=1, t=0.0, watchdog=5):
    fw = ActuatorFirmware(node, START_UM, PARAMS)
    fw.advance(t)
    [ack] = command(fw, CommandCode.ENABLE, 1, t, RATE, watchdog)
    assert ack.result is CommandResult.ACCEPTED and fw.state is ActuatorState.ENABLED
    return fw


def send_cycle(fw, counter, setpoint_um, t):
    """One classic cycle with every node's set-point ``setpoint_um``; the firmware's answers."""
    out = []
    for frame in codec.encode_setpoints(counter, [setpoint_um] * 6):
        out += fw.receive(*frame, t)
    return out


def stream(fw, counters, setpoints, t0):
    """Cycles every T from ``t0``; returns the time after the last."""
    t = t0
    for counter, setpoint in zip(counters, setpoints):
        t += T
        send_cycle(fw, counter & 0xFF, setpoint, t)
    return t


# -- boot, heartbeat, feedback ------------------------------------------------------------


def test_boots_into_disabled_and_announces_itself():
    fw = ActuatorFirmware(3, START_UM, PARAMS)
    assert fw.state is ActuatorState.INIT
    [heartbeat] = decoded(fw.advance(0.0))
    assert heartbeat == Heartbeat(3, ActuatorState.DISABLED, 0, codec.PROTOCOL_VERSION, 0)


def test_heartbeat_every_100_ms_with_counter():
    fw = ActuatorFirmware(1, START_UM, PARAMS)
    beats = []
    for step in range(0, 1001):
        beats += of_type(fw.advance(step * 0.001), Heartbeat)
    assert [beat.counter for beat in beats] == list(range(11))


def test_sync_schedules_feedback_in_every_state_spread_over_cycles():
    # Before any ENABLE the initial loop rate (500 Hz: every second SYNC) applies.
    fws = [ActuatorFirmware(node, START_UM, PARAMS) for node in codec.NODE_IDS]
    for fw in fws:
        fw.advance(0.0)
    senders = {}
    for counter in range(4):
        sync = codec.encode_sync(counter)
        senders[counter] = [f.node for f in fws for m in of_type(f.receive(*sync, 0.001 * counter), Feedback)]
    assert senders == {0: [1, 3, 5], 1: [2, 4, 6], 2: [1, 3, 5], 3: [2, 4, 6]}


def test_feedback_reports_quantised_position_and_state():
    fw = ActuatorFirmware(2, 123_456.7, PARAMS)
    fw.advance(0.0)
    [feedback] = of_type(fw.receive(*codec.encode_sync(1), 0.001), Feedback)
    assert feedback == Feedback(2, 123_457, 0, ActuatorState.DISABLED, Fault(0), 0)


# -- set-points -------------------------------------------------------------------------


def test_setpoint_is_applied_at_the_sync_with_its_counter_only():
    fw = enabled()
    setpoint_12 = codec.encode_setpoints(7, [START_UM + 500] * 6)[0]
    fw.receive(*setpoint_12, 0.001)
    assert fw.target_um == START_UM  # latched, not applied
    fw.receive(*codec.encode_sync(8), 0.0015)  # another cycle's SYNC: missed cycle
    assert fw.target_um == START_UM
    fw.receive(*setpoint_12, 0.002)
    fw.receive(*codec.encode_sync(7), 0.002)
    assert (fw.target_um, fw.setpoint_counter) == (START_UM + 500, 7)


def test_actuator_follows_a_ramp_and_settles():
    fw = enabled()
    ramp = [START_UM + 600 * k for k in range(1, 201)]  # 300 mm/s, then hold
    stream(fw, range(300), ramp + [ramp[-1]] * 100, 0.0)
    assert fw.sensor_um == ramp[-1]
    assert fw.state is ActuatorState.ENABLED and fw.faults == Fault(0)


@pytest.mark.parametrize("payload_fix", ["crc", "dlc"])
def test_corrupt_frames_are_rejected_counted_and_never_move(payload_fix):
    fw = enabled()
    can_id, payload = codec.encode_setpoints(0, [START_UM + 500] * 6)[0]
    bad = payload[:-1] + bytes((payload[-1] ^ 0xFF,)) if payload_fix == "crc" else payload[:-1]
    fw.receive(can_id, bad, 0.001)
    fw.receive(*codec.encode_sync(0), 0.001)
    fw.advance(0.05)
    assert fw.target_um == START_UM and fw.sensor_um == START_UM
    assert fw.rejected_total == 1
    [heartbeat] = of_type(fw.advance(0.1), Heartbeat)
    assert heartbeat.rejected_frames == 1


def test_stale_and_replayed_counters_are_rejected():
    fw = enabled()
    t = stream(fw, range(10), [START_UM + 100 * k for k in range(1, 11)], 0.0)  # last applied: 9
    target = fw.target_um
    for counter in (9, 3):  # a repeat (stale) and a replay from the past
        send_cycle(fw, counter, START_UM + 5_000, t)
    assert fw.target_um == target and fw.setpoint_counter == 9
    assert fw.rejected_total == 4  # SETPOINT_12 and SYNC of each
    assert fw.state is ActuatorState.ENABLED


def test_counter_wraps_around():
    fw = enabled()
    stream(fw, range(250, 262), [START_UM + 100 * k for k in range(1, 13)], 0.0)
    assert fw.setpoint_counter == 261 & 0xFF and fw.rejected_total == 0
    assert fw.target_um == START_UM + 1200


def test_out_of_stroke_setpoint_is_refused_with_a_fault():
    fw = ActuatorFirmware(1, 849_900, PARAMS)
    fw.advance(0.0)
    command(fw, CommandCode.ENABLE, 1, 0.0, RATE, 5)
    out = send_cycle(fw, 0, 850_001, 0.002)
    assert fw.state is ActuatorState.FAULT and fw.faults == Fault.SETPOINT_RANGE
    [emcy] = of_type(out, Emergency)
    assert emcy.fault_code is FaultCode.SETPOINT_RANGE
    assert fw.target_um == 849_900


def test_step_above_the_speed_limit_is_refused():
    fw = enabled()
    largest = 400_000 * T  # 800 µm per cycle
    send_cycle(fw, 0, START_UM + round(largest), 0.002)
    assert fw.state is ActuatorState.ENABLED
    send_cycle(fw, 1, START_UM + round(largest) + round(largest) + 2, 0.004)
    assert fw.faults == Fault.SETPOINT_RANGE


def test_step_rule_allows_for_missed_cycles():
    fw = enabled()
    send_cycle(fw, 0, START_UM, 0.002)
    send_cycle(fw, 3, START_UM + 2_400, 0.008)  # three cycles' worth after two missed
    assert fw.state is ActuatorState.ENABLED and fw.target_um == START_UM + 2_400


# -- watchdog ---------------------------------------------------------------------------


def test_watchdog_expires_after_n_and_a_half_cycles_and_latches():
    fw = enabled(watchdog=5)
    t = stream(fw, range(3), [START_UM] * 3, 0.0)
    fw.advance(t + 5.4 * T)
    assert fw.state is ActuatorState.ENABLED
    out = fw.advance(t + 5.6 * T)
    assert fw.state is ActuatorState.FAULT and fw.faults == Fault.COMM_TIMEOUT
    assert [e.fault_code for e in of_type(out, Emergency)] == [FaultCode.COMM_TIMEOUT]
    # Set-points alone do not resume.
    stream(fw, range(3, 8), [START_UM] * 5, t + 6 * T)
    assert fw.state is ActuatorState.FAULT and fw.target_um == START_UM


def test_watchdog_recovery_takes_clear_fault_then_enable():
    fw = enabled()
    fw.advance(1.0)
    assert fw.faults == Fault.COMM_TIMEOUT
    [ack] = command(fw, CommandCode.ENABLE, 2, 1.0, RATE, 5)
    assert ack.result is CommandResult.REJECTED_STATE
    out = command(fw, CommandCode.CLEAR_FAULT, 3, 1.0)
    assert out == [Emergency(1, FaultCode.NONE, ActuatorState.DISABLED, Fault(0)),
                   CommandAck(1, CommandCode.CLEAR_FAULT, 3, CommandResult.ACCEPTED, ActuatorState.DISABLED)]
    [ack] = command(fw, CommandCode.ENABLE, 4, 1.0, RATE, 5)
    assert ack.result is CommandResult.ACCEPTED
    # After ENABLE any counter starts the stream (there is no "last" any more).
    send_cycle(fw, 200, START_UM + 100, 1.002)
    assert fw.setpoint_counter == 200 and fw.state is ActuatorState.ENABLED


def test_watchdog_runs_in_locked_and_set_points_feed_it_without_moving():
    fw = enabled()
    command(fw, CommandCode.LOCK, 2, 0.0)
    t = stream(fw, range(50), [START_UM + 100 * k for k in range(1, 51)], 0.0)
    assert fw.state is ActuatorState.LOCKED and fw.setpoint_counter == 49
    assert fw.sensor_um == START_UM
    fw.advance(t + 10 * T)
    assert fw.state is ActuatorState.FAULT and fw.faults == Fault.COMM_TIMEOUT


# -- commands ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("loop_rate", "watchdog"), [(LoopRate.NOT_SET, 5), (RATE, 2), (RATE, 101)]
)
def test_enable_with_invalid_arguments_is_refused(loop_rate, watchdog):
    fw = ActuatorFirmware(1, START_UM, PARAMS)
    fw.advance(0.0)
    [ack] = command(fw, CommandCode.ENABLE, 1, 0.0, loop_rate, watchdog)
    assert ack.result is CommandResult.REJECTED_ARGUMENT and fw.state is ActuatorState.DISABLED


@pytest.mark.parametrize(
    ("state_commands", "code", "result", "after"),
    [
        ((), CommandCode.DISABLE, CommandResult.ACCEPTED, ActuatorState.DISABLED),
        ((), CommandCode.LOCK, CommandResult.REJECTED_STATE, ActuatorState.DISABLED),
        ((), CommandCode.UNLOCK, CommandResult.REJECTED_STATE, ActuatorState.DISABLED),
        ((), CommandCode.CLEAR_FAULT, CommandResult.ACCEPTED, ActuatorState.DISABLED),
        ((CommandCode.ENABLE,), CommandCode.ENABLE, CommandResult.REJECTED_STATE, ActuatorState.ENABLED),
        ((CommandCode.ENABLE,), CommandCode.LOCK, CommandResult.ACCEPTED, ActuatorState.LOCKED),
        ((CommandCode.ENABLE,), CommandCode.UNLOCK, CommandResult.REJECTED_STATE, ActuatorState.ENABLED),
        ((CommandCode.ENABLE,), CommandCode.DISABLE, CommandResult.ACCEPTED, ActuatorState.DISABLED),
        ((CommandCode.ENABLE, CommandCode.LOCK), CommandCode.LOCK, CommandResult.ACCEPTED, ActuatorState.LOCKED),
        ((CommandCode.ENABLE, CommandCode.LOCK), CommandCode.UNLOCK, CommandResult.ACCEPTED, ActuatorState.ENABLED),
        ((CommandCode.ENABLE, CommandCode.LOCK), CommandCode.DISABLE, CommandResult.ACCEPTED, ActuatorState.DISABLED),
        ((CommandCode.ENABLE, CommandCode.LOCK), CommandCode.ENABLE, CommandResult.REJECTED_STATE, ActuatorState.LOCKED),
    ],
)
def test_transition_table(state_commands, code, result, after):
    fw = ActuatorFirmware(1, START_UM, PARAMS)
    fw.advance(0.0)
    for sequence, earlier in enumerate(state_commands, start=1):
        command(fw, earlier, sequence, 0.0, RATE, 5)
    [ack] = command(fw, code, 50, 0.0, RATE if code is CommandCode.ENABLE else LoopRate.NOT_SET,
                    5 if code is CommandCode.ENABLE else 0)
    assert (ack.result, ack.state, fw.state) == (result, after, after)


def test_repeated_sequence_is_acknowledged_again_but_not_executed_again():
    fw = enabled()
    [first] = command(fw, CommandCode.LOCK, 9, 0.0)
    [unlock] = command(fw, CommandCode.UNLOCK, 10, 0.0)
    [again] = command(fw, CommandCode.UNLOCK, 10, 0.0)  # a retry of the UNLOCK
    assert first.result is unlock.result is again.result is CommandResult.ACCEPTED
    assert fw.state is ActuatorState.ENABLED


def test_corrupt_command_gets_no_ack_and_is_counted():
    fw = ActuatorFirmware(1, START_UM, PARAMS)
    fw.advance(0.0)
    can_id, payload = codec.encode_command(1, CommandCode.ENABLE, 1, RATE, 5)
    assert fw.receive(can_id, payload[:-1] + bytes((payload[-1] ^ 1,)), 0.0) == []
    assert fw.state is ActuatorState.DISABLED and fw.rejected_total == 1


def test_other_nodes_frames_are_ignored():
    fw = enabled(node=1)
    send_cycle(fw, 0, START_UM + 100, 0.002)
    assert fw.receive(*codec.encode_command(2, CommandCode.DISABLE, 5), 0.003) == []
    assert fw.state is ActuatorState.ENABLED and fw.rejected_total == 0


# -- lock, stop, estop ------------------------------------------------------------------


def test_locked_actuator_holds_its_length_whatever_arrives():
    fw = enabled()
    t = stream(fw, range(70), [START_UM + 500 * k for k in range(1, 21)] + [START_UM + 10_000] * 50, 0.0)
    held = fw.position_um
    command(fw, CommandCode.LOCK, 2, t)
    stream(fw, range(70, 170), [850_000 + 10_000 * k for k in range(100)], t)
    assert fw.position_um == held and fw.state is ActuatorState.LOCKED and fw.faults == Fault(0)


def test_unlock_resumes_from_the_measured_position():
    fw = enabled()
    command(fw, CommandCode.LOCK, 2, 0.0)
    t = stream(fw, range(10), [START_UM + 50_000] * 10, 0.0)  # far away: ignored while locked
    command(fw, CommandCode.UNLOCK, 3, t)
    assert fw.target_um == START_UM
    send_cycle(fw, 10, START_UM + 50_000, t + T)  # the same far set-point is now a step: refused
    assert fw.faults == Fault.SETPOINT_RANGE


def test_disable_makes_a_controlled_stop():
    fw = enabled()
    t = stream(fw, range(100), [START_UM + 800 * k for k in range(1, 101)], 0.0)  # 400 mm/s
    moving = fw.velocity_um_s
    command(fw, CommandCode.DISABLE, 2, t)
    positions = []
    for k in range(1, 100):
        fw.advance(t + k * 0.001)
        positions.append(fw.position_um)
    stop_distance = moving**2 / (2 * PARAMS.max_acceleration_um_s2)
    assert fw.velocity_um_s == 0.0 and fw.state is ActuatorState.DISABLED
    assert positions[-1] - positions[0] <= stop_distance + moving * 0.001


@pytest.mark.parametrize("payload, logged", [(b"", None), (bytes((EStopReason.SAFETY_CHAIN,)), EStopReason.SAFETY_CHAIN),
                                             (b"\xff\xff\xff", None), (b"\x09", None)])
def test_estop_acts_on_the_identifier_whatever_the_payload_and_logs_its_reason(payload, logged):
    fw = enabled()
    out = fw.receive(codec.FrameId.ESTOP, payload, 0.001)
    assert fw.state is ActuatorState.ESTOP and fw.faults == Fault.ESTOP
    assert of_type(out, Emergency) == [Emergency(1, FaultCode.ESTOP, ActuatorState.ESTOP, Fault.ESTOP)]
    assert fw.last_estop_reason == logged


def test_estop_wins_over_fault_and_clears_only_after_250_ms():
    fw = enabled()
    fw.advance(1.0)  # watchdog: FAULT
    fw.receive(*codec.encode_estop(EStopReason.OPERATOR), 1.0)
    assert fw.state is ActuatorState.ESTOP and fw.faults == Fault.COMM_TIMEOUT | Fault.ESTOP
    send_cycle(fw, 0, START_UM + 100, 1.01)
    command(fw, CommandCode.DISABLE, 2, 1.1)
    [early] = command(fw, CommandCode.CLEAR_FAULT, 3, 1.2)
    assert early.result is CommandResult.REJECTED_FAULT_ACTIVE and fw.state is ActuatorState.ESTOP
    [_, late] = command(fw, CommandCode.CLEAR_FAULT, 4, 1.3)
    assert late.result is CommandResult.ACCEPTED and fw.state is ActuatorState.DISABLED
    assert fw.faults == Fault(0) and fw.sensor_um == START_UM


# -- injected faults --------------------------------------------------------------------


def test_sensor_fault_latches_and_persists_until_its_cause_is_gone():
    fw = enabled()
    fw.inject.sensor_fault = True
    out = fw.advance(0.001)
    assert fw.faults == Fault.SENSOR and [e.fault_code for e in of_type(out, Emergency)] == [FaultCode.SENSOR]
    [ack] = command(fw, CommandCode.CLEAR_FAULT, 2, 0.01)
    assert ack.result is CommandResult.REJECTED_FAULT_ACTIVE
    fw.inject.sensor_fault = False
    [emcy, ack] = command(fw, CommandCode.CLEAR_FAULT, 3, 0.02)
    assert emcy.fault_code is FaultCode.NONE
    assert ack.result is CommandResult.ACCEPTED and fw.state is ActuatorState.DISABLED


def test_stalled_drive_trips_following_error():
    fw = enabled()
    fw.inject.stall = True
    stream(fw, range(60), [START_UM + 800 * k for k in range(1, 61)], 0.0)
    assert fw.faults & Fault.FOLLOWING_ERROR and fw.state is ActuatorState.FAULT
    assert fw.sensor_um == START_UM


def test_emergencies_are_rate_limited_but_faults_still_latch():
    fw = enabled()
    fw.inject.sensor_fault = True
    first = of_type(fw.advance(0.001), Emergency)
    second = of_type(fw.receive(*codec.encode_estop(EStopReason.OPERATOR), 0.005), Emergency)
    assert len(first) == 1 and second == []
    assert fw.faults == Fault.SENSOR | Fault.ESTOP


def test_dropped_and_corrupted_frames():
    fw = enabled()
    fw.inject.drop_next = 2  # SETPOINT_12 and SYNC of cycle 0 are lost
    send_cycle(fw, 0, START_UM + 100, 0.002)
    assert fw.setpoint_counter == 0 and fw.target_um == START_UM and fw.rejected_total == 0
    fw.inject.corrupt_next = 1  # cycle 1's SETPOINT_12 arrives corrupted: missed cycle
    send_cycle(fw, 1, START_UM + 100, 0.004)
    assert fw.target_um == START_UM and fw.rejected_total == 1
    send_cycle(fw, 2, START_UM + 100, 0.006)
    assert fw.target_um == START_UM + 100


def test_silent_actuator_sends_nothing_but_keeps_working():
    fw = enabled()
    fw.inject.silent = True
    assert fw.advance(0.5) == [] and fw.faults == Fault.COMM_TIMEOUT


def test_probabilistic_faults_repeat_with_the_seed():
    def rejected(seed):
        fw = ActuatorFirmware(1, START_UM, PARAMS, inject=FaultInjection(corrupt_probability=0.3, seed=seed))
        fw.advance(0.0)
        command(fw, CommandCode.ENABLE, 1, 0.0, RATE, 100)
        stream(fw, range(100), [START_UM] * 100, 0.0)
        return fw.rejected_total

    assert rejected(7) == rejected(7)
    assert 20 < rejected(7) < 100


def test_fd_frame_is_its_own_sync():
    fw = enabled(node=4)
    can_id, payload = codec.encode_setpoints_fd(0, [START_UM + 100 * n for n in codec.NODE_IDS])
    fw.receive(can_id, payload, 0.002)
    assert fw.target_um == START_UM + 400 and fw.setpoint_counter == 0
