"""The link against a fake bus: send failures, bad frames, bus states, counters, threads."""

from __future__ import annotations

import errno
import math
import os
import threading
from collections import deque

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_proto import codec
from firmware_proto.codec import ActuatorState as WireState
from firmware_proto.codec import CommandCode, CommandResult, EStopReason, Fault, LoopRate
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.can import transport
from hexactl.adapters.can.transport import BusSpec, BusSpecError, open_bus, parse_bus_spec
from hexactl.control.hardware import ActuatorCommand, ActuatorInterface, ActuatorState, BusState, EstopCause
from tests.firmware_proto.frames import dbc_fault_names

ENOBUFS = can.CanOperationError("Failed to transmit: No buffer space available", errno.ENOBUFS)
ENETDOWN = can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
SIX = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0]


class FakeBus:
    """Records sent frames; ``fail`` (an exception) makes sends raise; ``incoming`` feeds recv."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []
        self.timeouts: list[float | None] = []
        self.fail: Exception | None = None
        self.fail_after: int | None = None  # succeed this many more sends, then raise ``fail``
        self.incoming: deque[can.Message] = deque()
        self.recv_error: Exception | None = None

    def send(self, message: can.Message, timeout: float | None = None) -> None:
        if self.fail is not None:
            if self.fail_after is None or self.fail_after == 0:
                raise self.fail
            self.fail_after -= 1
        self.sent.append((message.arbitration_id, bytes(message.data)))
        self.timeouts.append(timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.recv_error is not None:
            raise self.recv_error
        return self.incoming.popleft() if self.incoming else None

    def shutdown(self) -> None:
        pass

    def push(self, can_id: int, payload: bytes, **flags: bool) -> None:
        self.incoming.append(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False, **flags))


def without_syncs(frames: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
    """Leave out the bare SYNCs that read_feedback sends when no cycle was sent."""
    return [frame for frame in frames if frame[0] != codec.FrameId.SYNC]


class Clock:
    def __init__(self) -> None:
        self.t_ns = 0

    def __call__(self) -> int:
        return self.t_ns


@pytest.fixture
def bus() -> FakeBus:
    return FakeBus()


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def link(bus: FakeBus, clock: Clock) -> CanActuatorLink:
    return CanActuatorLink(bus, LinkConfig(), clock_ns=clock)  # type: ignore[arg-type]


def greet(bus: FakeBus, link: CanActuatorLink, version: int = codec.PROTOCOL_VERSION) -> None:
    """Every actuator sends a HEARTBEAT in DISABLED."""
    for node in codec.NODE_IDS:
        bus.push(*codec.encode_heartbeat(node, WireState.DISABLED, 0, version))
    link.read_feedback()


def test_implements_the_control_layers_interface(link):
    assert isinstance(link, ActuatorInterface)


# -- spec strings ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "parsed"),
    [("socketcan:can0", BusSpec("socketcan", "can0")), ("socketcan:vcan0", BusSpec("socketcan", "vcan0")),
     ("virtual:bench", BusSpec("virtual", "bench")), (" virtual:a:b ", BusSpec("virtual", "a:b")),
     ("memory:sim", BusSpec("memory", "sim"))],
)
def test_bus_specs(spec, parsed):
    assert parse_bus_spec(spec) == parsed
    assert str(parsed) == f"{parsed.interface}:{parsed.channel}"


@pytest.mark.parametrize("spec", ["can0", "socketcan:", "pcan:PCAN_USBBUS1", ":vcan0", ""])
def test_bad_bus_specs(spec):
    with pytest.raises(BusSpecError, match="socketcan:CHANNEL"):
        parse_bus_spec(spec)


@pytest.mark.parametrize(("spec", "code", "says"), [
    ("socketcan:can0", errno.ENODEV, "bring it up with: ip link set can0 type can bitrate 1000000 && ip link set can0 up"),
    ("socketcan:vcan0", errno.ENODEV, "bring it up with: ip link add dev vcan0 type vcan && ip link set vcan0 up"),
    ("socketcan:can0", errno.EAFNOSUPPORT, "this kernel has no SocketCAN: load it with modprobe can_raw"),
    ("socketcan:can0", errno.EPERM, "Operation not permitted"),  # no usual cause to name: as the OS says
])
def test_a_socketcan_bus_that_cannot_open_says_what_to_do(monkeypatch, spec, code, says):
    def refuse(channel, **options):  # as python-can's SocketcanBus: the OS error from socket() or bind()
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(transport, "LeanSocketcanBus", refuse)
    with pytest.raises(OSError) as refused:
        open_bus(spec)
    assert refused.value.errno == code and says in str(refused.value)


# -- set-points -----------------------------------------------------------------------------


def test_setpoints_are_one_cycle_of_codec_frames_in_um(link, bus):
    assert link.send_setpoints(300, [100.0004, 200.0005, 300.0006, -0.0004, 8388.607, 0.0])
    assert bus.sent == list(codec.encode_setpoints(300 & 0xFF, [100_000, 200_000, 300_001, 0, 8_388_607, 0]))
    assert bus.timeouts == [0.0] * 4


@pytest.mark.parametrize(
    "values",
    [[math.nan] + SIX[1:], SIX[:5] + [math.inf], SIX[:5] + [-math.inf], SIX[:5] + [8388.608], SIX[:5], SIX + [1.0]],
)
def test_unsendable_setpoints_are_refused_and_counted(link, bus, values):
    assert link.send_setpoints(1, values) is False
    assert bus.sent == []
    assert link.stats().refused_setpoints == 1 and link.link_health().send_failures == 1
    assert "refused" in link.link_health().detail


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=6, max_size=6))
def test_setpoints_are_sent_exactly_when_encodable(values):
    bus = FakeBus()
    link = CanActuatorLink(bus, LinkConfig(), clock_ns=Clock())  # type: ignore[arg-type]
    encodable = all(math.isfinite(v * 1000) and -(2**23) <= round(v * 1000) < 2**23 for v in values)
    assert link.send_setpoints(5, values) is encodable
    assert len(bus.sent) == (4 if encodable else 0)


def test_send_failure_is_counted_never_raised_and_drops_the_cycle(link, bus):
    bus.fail = ENOBUFS
    assert link.send_setpoints(10, SIX) is False
    health = link.link_health()
    assert health.send_failures == 1 and health.bus_state is BusState.ACTIVE
    assert "No buffer space" in health.detail


def test_failure_mid_cycle_withholds_the_sync(link, bus):
    bus.fail, bus.fail_after = ENOBUFS, 2  # SETPOINT_12 and SETPOINT_34 go out, SETPOINT_56 fails
    assert link.send_setpoints(10, SIX) is False
    assert [can_id for can_id, _ in bus.sent] == [codec.FrameId.SETPOINT_12, codec.FrameId.SETPOINT_34]


def test_nothing_stale_is_sent_after_a_failure(link, bus):
    bus.fail = ENOBUFS
    for counter in range(10, 15):
        assert not link.send_setpoints(counter, [v + counter for v in SIX])
    bus.fail = None
    assert link.send_setpoints(15, [v + 15 for v in SIX])
    link.read_feedback()
    assert bus.sent == list(codec.encode_setpoints(15, [round((v + 15) * 1000) for v in SIX]))
    assert link.link_health().send_failures == 5


def test_interface_down_and_back(link, bus):
    bus.fail = ENETDOWN
    link.send_setpoints(1, SIX)
    assert link.link_health().bus_state is BusState.DOWN
    bus.fail = None
    assert link.send_setpoints(2, SIX)
    assert link.link_health().bus_state is BusState.ACTIVE


def test_unexpected_exception_from_the_driver_is_a_counted_failure(link, bus):
    bus.fail = RuntimeError("driver bug")
    assert link.send_estop() is False
    assert link.send_command(1, ActuatorCommand.DISABLE) is False
    assert link.link_health().send_failures == 2


def test_bare_sync_keeps_the_cycle_when_no_setpoints_were_sent(link, bus):
    link.read_feedback()  # nothing sent yet: SYNC 0
    link.send_setpoints(41, [math.nan] * 6)  # refused: nothing on the bus
    link.read_feedback()
    link.send_setpoints(42, SIX)
    link.read_feedback()  # a cycle was sent: no SYNC
    link.read_feedback()  # SYNC 43: after the last counter sent, never completing an old cycle
    syncs = [codec.decode(*frame).counter for frame in bus.sent if frame[0] == codec.FrameId.SYNC]
    assert syncs == [0, 1, 42, 43]


def test_closed_link_is_down_and_fails_quietly(bus, clock):
    link = CanActuatorLink(bus, clock_ns=clock)  # type: ignore[arg-type]
    link.close()
    bus.fail = can.CanOperationError("Cannot operate on a closed bus")
    assert link.send_setpoints(0, SIX) is False
    assert link.read_feedback().actuators[0].heartbeat_age_s == math.inf
    assert link.link_health().bus_state is BusState.DOWN


@pytest.mark.parametrize("cause, reason", [(EstopCause.OPERATOR, EStopReason.OPERATOR),
                                           (EstopCause.SAFETY_CHAIN, EStopReason.SAFETY_CHAIN),
                                           (EstopCause.CONTROLLER_FAULT, EStopReason.CONTROLLER_FAULT)])
def test_estop_waits_briefly_and_carries_its_reason(link, bus, cause, reason):
    assert link.send_estop(cause)
    assert bus.sent == [codec.encode_estop(reason)]
    assert bus.timeouts == [LinkConfig().estop_send_timeout_s]


def test_failure_counting_is_thread_safe(link, bus):
    bus.fail = ENOBUFS
    calls = 2000

    def estops():
        for _ in range(calls):
            link.send_estop()

    thread = threading.Thread(target=estops)
    thread.start()
    for counter in range(calls):
        link.send_setpoints(counter, SIX)
    thread.join()
    assert link.link_health().send_failures == 2 * calls


# -- commands -------------------------------------------------------------------------------


def test_enable_carries_loop_rate_and_watchdog_and_sequences_advance(bus, clock):
    link = CanActuatorLink(bus, LinkConfig(loop_rate=LoopRate.HZ_250, watchdog_cycles=8), clock_ns=clock)  # type: ignore[arg-type]
    greet(bus, link)
    assert link.send_command(3, ActuatorCommand.ENABLE)
    assert link.send_command(3, ActuatorCommand.LOCK)
    first, enable, lock = (codec.decode(*frame) for frame in without_syncs(bus.sent))
    # the first command to a leg goes behind a DISABLE (test_link_with_simulator.py)
    assert (first.command, first.sequence) == (CommandCode.DISABLE, (enable.sequence - 1) & 0xFF)
    assert (enable.node, enable.command, enable.loop_rate, enable.watchdog_cycles) == (3, CommandCode.ENABLE, 250, 8)
    assert (lock.command, lock.loop_rate, lock.watchdog_cycles) == (CommandCode.LOCK, LoopRate.NOT_SET, 0)
    assert lock.sequence == (enable.sequence + 1) & 0xFF


def test_command_to_all_legs(link, bus):
    assert link.send_command(None, ActuatorCommand.CLEAR_FAULT)
    assert [codec.decode(*frame).node for frame in bus.sent] == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize("version", [None, 2])
def test_enable_needs_a_heartbeat_with_this_protocol_version(link, bus, version):
    if version is not None:
        greet(bus, link, version)
    assert link.send_command(1, ActuatorCommand.ENABLE) is False
    assert without_syncs(bus.sent) == [] and link.link_health().send_failures == 1
    assert "ENABLE refused for leg 1" in link.link_health().detail


def test_health_names_a_leg_speaking_another_protocol_version(link, bus):
    greet(bus, link)
    bus.push(*codec.encode_heartbeat(4, WireState.DISABLED, 1, codec.PROTOCOL_VERSION + 1))
    feedback = link.read_feedback()
    assert feedback.actuators[3].heartbeat_age_s == math.inf  # the loop must not count it present ...
    health = link.link_health()  # ... and is told why, though its frames arrive
    assert health.bus_state is BusState.ACTIVE and link.silent_legs() == ()
    assert health.detail == "leg 4 speaks protocol version 2, this controller 1: it is not enabled while it does"


def test_bad_leg_is_refused(link, bus):
    assert link.send_command(7, ActuatorCommand.DISABLE) is False
    assert bus.sent == []


def test_unacknowledged_command_is_retried_with_its_sequence_then_given_up(link, bus, clock):
    link.send_command(2, ActuatorCommand.DISABLE)
    for _ in range(5):
        clock.t_ns += 20_000_000
        link.read_feedback()
    commands = without_syncs(bus.sent)
    assert len(commands) == 4 and len(set(commands)) == 1  # the command and 3 identical retries
    assert link.stats().command_timeouts == 1 and not link.node_status(2).command_pending


def test_acknowledged_command_is_not_retried(link, bus, clock):
    link.send_command(2, ActuatorCommand.DISABLE)
    sequence = codec.decode(*bus.sent[0]).sequence
    bus.push(*codec.encode_command_ack(2, CommandCode.DISABLE, sequence, codec.CommandResult.ACCEPTED, WireState.DISABLED))
    clock.t_ns += 100_000_000
    link.read_feedback()
    assert len(without_syncs(bus.sent)) == 1 and link.node_status(2).last_ack.sequence == sequence


# -- receiving ------------------------------------------------------------------------------


def test_feedback_heartbeat_and_emergency_become_actuator_state(link, bus, clock):
    bus.push(*codec.encode_feedback(1, 123_456, -2_500, WireState.ENABLED, Fault(0), 0))
    bus.push(*codec.encode_heartbeat(2, WireState.LOCKED, 7))
    bus.push(*codec.encode_emergency(3, codec.FaultCode.SENSOR, WireState.FAULT, Fault.SENSOR | Fault.ESTOP))
    clock.t_ns = 5_000_000
    snapshot = link.read_feedback()
    one, two, three, four = snapshot.actuators[:4]
    assert (one.position_mm, one.velocity_mm_s, one.state) == (123.456, -2.5, ActuatorState.ENABLED)
    assert two.state is ActuatorState.LOCKED and math.isnan(two.position_mm)
    assert three.state is ActuatorState.FAULT and three.fault_bits == int(Fault.SENSOR | Fault.ESTOP)
    assert three.fault_names == ("estop", "sensor") and one.fault_names == ()
    assert four.heartbeat_age_s == math.inf and four.state is ActuatorState.DISABLED
    assert one.heartbeat_age_s == math.inf  # FEEDBACK alone: not yet known to speak protocol 1
    assert two.heartbeat_age_s == 0.0  # heard at this read
    bus.push(*codec.encode_heartbeat(1, WireState.ENABLED, 0))
    link.read_feedback()
    clock.t_ns = 105_000_000
    assert link.read_feedback().actuators[0].heartbeat_age_s == pytest.approx(0.1)
    assert link.stats().emergencies == (0, 0, 1, 0, 0, 0)


def test_every_fault_bit_is_named_as_the_dbc_names_it(link, bus):
    names = dbc_fault_names()
    assert sorted(names) == list(range(12))
    for bit, name in names.items():
        bus.push(*codec.encode_feedback(4, 0, 0, WireState.FAULT, Fault(1 << bit), 0))
        assert link.read_feedback().actuators[3].fault_names == (name.lower(),), name
    bus.push(*codec.encode_emergency(4, codec.FaultCode.INTERNAL, WireState.FAULT, Fault((1 << 12) - 1)))
    every = link.read_feedback().actuators[3]
    assert (every.fault_bits, every.fault_names) == (0xFFF, tuple(names[bit].lower() for bit in range(12)))


def test_bad_frames_are_counted_not_raised(link, bus):
    bus.push(0x181, b"\x00\x01")  # FEEDBACK_1 with a bad DLC
    bus.push(0x187, bytes(8))  # FEEDBACK of node 7
    bus.push(0x555, b"")  # not in the protocol
    bus.push(0x701, bytes((9, 0, 1, 0)))  # HEARTBEAT with state 9
    bus.incoming.append(can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=True))
    bus.push(*codec.encode_setpoints(0, [0] * 6)[0])  # another controller's frame
    snapshot = link.read_feedback()
    assert link.stats().undecodable_frames == 5 and link.stats().foreign_frames == 1
    assert all(math.isnan(a.position_mm) for a in snapshot.actuators)


@pytest.mark.parametrize(("frame", "name"), [
    (codec.encode_sync(7), "SYNC"),
    (codec.encode_setpoints(7, [0] * 6)[1], "SETPOINT_34"),
    (codec.encode_command(3, CommandCode.ENABLE, 9, LoopRate.HZ_500, 5), "CMD_3 ENABLE"),
])
def test_another_controllers_frame_is_named_with_when_it_was_heard(link, bus, clock, frame, name):
    assert link.link_health().other_controller_age_s == math.inf  # none heard yet
    clock.t_ns = 1_000_000_000
    bus.push(*frame)
    link.read_feedback()
    clock.t_ns += 250_000_000
    health = link.link_health()
    assert (health.other_controller_frame, health.other_controller_age_s) == (name, pytest.approx(0.25))


def test_an_estop_from_elsewhere_is_no_other_controller(link, bus):
    bus.push(*codec.encode_estop(EStopReason.SAFETY_CHAIN))  # a safety PLC or an E-stop node may send it
    link.read_feedback()
    assert link.stats().foreign_frames == 1
    assert (link.link_health().other_controller_age_s, link.link_health().other_controller_frame) == (math.inf, "")


def test_receive_error_marks_the_bus_down(link, bus):
    bus.recv_error = can.CanOperationError("Network is down", errno.ENETDOWN)
    link.read_feedback()
    assert link.link_health().bus_state is BusState.DOWN


@pytest.mark.parametrize(
    ("can_id", "data", "state"),
    [(0x040, bytes(8), BusState.BUS_OFF), (0x004, bytes((0, 0x20, 0, 0, 0, 0, 0, 0)), BusState.PASSIVE),
     (0x004, bytes((0, 0x08, 0, 0, 0, 0, 0, 0)), BusState.WARNING), (0x100, bytes(8), BusState.ACTIVE)],
)
def test_socketcan_error_frames_set_the_bus_state(link, bus, can_id, data, state):
    bus.push(0x040, bytes(8), is_error_frame=True)
    bus.push(can_id, data, is_error_frame=True)
    link.read_feedback()
    assert link.link_health().bus_state is BusState.BUS_OFF  # the read a bus-off came in says it, whatever came after
    link.read_feedback()
    assert link.link_health().bus_state is state


def test_read_drains_a_bounded_number_of_frames(bus, clock):
    link = CanActuatorLink(bus, LinkConfig(max_frames_per_read=10), clock_ns=clock)  # type: ignore[arg-type]
    for counter in range(25):
        bus.push(*codec.encode_heartbeat(1, WireState.DISABLED, counter))
    link.read_feedback()
    assert len(bus.incoming) == 15
    assert link.link_health().detail.endswith("; receiving behind: a read found 10 frames or more waiting, so what "
                                              "the actuators report reaches the loop late (the loop held up, or a "
                                              "flood on the bus: candump shows who sends)")
    link.read_feedback()
    link.read_feedback()
    assert not bus.incoming and link.stats().frames_received == 25
    clock.t_ns = int(LinkConfig().heartbeat_timeout_s * 1e9) + 1  # caught up since: said no longer
    assert "behind" not in link.link_health().detail


def test_setpoint_counter_is_unwrapped_to_the_loop_counter(link, bus):
    for counter in range(1000, 1300):
        link.send_setpoints(counter, SIX)
    bus.push(*codec.encode_feedback(1, 0, 0, WireState.ENABLED, Fault(0), 1297 & 0xFF))
    bus.push(*codec.encode_feedback(2, 0, 0, WireState.DISABLED, Fault(0), 1297 & 0xFF))
    first, second = link.read_feedback().actuators[:2]
    assert first.setpoint_counter == 1297
    assert second.setpoint_counter == -1  # never enabled: its counter means nothing yet


def test_counter_older_than_the_first_sent_is_none(link, bus):
    link.send_setpoints(5, SIX)
    bus.push(*codec.encode_feedback(1, 0, 0, WireState.ENABLED, Fault(0), 200))
    assert link.read_feedback().actuators[0].setpoint_counter == -1


def test_silent_legs_and_health_detail(link, bus, clock):
    greet(bus, link)
    clock.t_ns = 250_000_000
    bus.push(*codec.encode_heartbeat(3, WireState.DISABLED, 1))
    link.read_feedback()
    clock.t_ns = 350_000_000
    assert link.silent_legs() == (1, 2, 4, 5, 6)
    assert link.link_health().detail.startswith("silent legs: 1, 2, 4, 5, 6")
    assert link.node_status(3).heartbeat_age_s == pytest.approx(0.1)


def test_config_is_validated():
    with pytest.raises(ValueError, match="loop_rate"):
        LinkConfig(loop_rate=LoopRate.NOT_SET)
    with pytest.raises(ValueError, match="watchdog_cycles"):
        LinkConfig(watchdog_cycles=101)


# -- found from outside: a review of the CAN link ----------------------------------------

MS = 1_000_000


def sent_commands(bus: FakeBus) -> list[codec.Command]:
    return [codec.decode(*frame) for frame in without_syncs(bus.sent)]


class DeliversThenRaises(FakeBus):
    """As ``memory:`` with one receiver full: the frame reaches the others, then the send raises."""

    def send(self, message, timeout=None) -> None:
        self.sent.append((message.arbitration_id, bytes(message.data)))
        if self.fail is not None:
            raise self.fail


@pytest.mark.parametrize("delivered", [False, True])
def test_a_command_that_fails_to_send_supersedes_the_unacknowledged_one(clock, delivered):
    """Finding 1: the ENABLE leg 3 missed must not be retried after the DISABLE that followed
    it failed to send; the DISABLE is retried instead (with its own sequence, so an actuator
    that did receive it acknowledges the retry without executing it twice)."""
    bus = DeliversThenRaises() if delivered else FakeBus()
    link = CanActuatorLink(bus, LinkConfig(), clock_ns=clock)  # type: ignore[arg-type]
    greet(bus, link)
    assert link.send_command(3, ActuatorCommand.ENABLE)  # sent, never acknowledged
    bus.fail = ENOBUFS
    assert link.send_command(3, ActuatorCommand.DISABLE) is False
    bus.fail = None
    for _ in range(3):
        clock.t_ns += 20 * MS
        link.read_feedback()
    _, enable, *disables = sent_commands(bus)  # the first command to a leg goes behind a DISABLE
    assert enable.command is CommandCode.ENABLE
    assert [command.command for command in disables] == [CommandCode.DISABLE] * (4 if delivered else 3)
    assert {command.sequence for command in disables} == {(enable.sequence + 1) & 0xFF}


def enabled_at(link: CanActuatorLink, bus: FakeBus, node: int, counter: int) -> None:
    """Leg ``node`` reports FEEDBACK in ENABLED having applied loop counter ``counter``."""
    bus.push(*codec.encode_feedback(node, 0, 0, WireState.ENABLED, Fault(0), counter & 0xFF))


def test_a_rebooted_actuators_counter_is_unknown_until_it_echoes_one_sent_after_its_enable(link, bus):
    """Finding 2: after a reboot the actuator echoes SetpointCounter 0, which unwraps to a
    counter long past (1024 here): the link reports −1 until an echo of a counter it sent
    after the ENABLE."""
    greet(bus, link)
    for counter in range(1000, 1030):
        link.send_setpoints(counter, SIX)
    enabled_at(link, bus, 3, 1029)
    assert link.read_feedback().actuators[2].setpoint_counter == 1029
    bus.push(*codec.encode_heartbeat(3, WireState.DISABLED, 0))  # rebooted: DISABLED, counter 0
    assert link.read_feedback().actuators[2].setpoint_counter == -1  # left ENABLED: applies nothing
    for counter in range(1030, 1095):
        link.send_setpoints(counter, SIX)
    assert link.send_command(3, ActuatorCommand.ENABLE)
    sequence = codec.decode(*bus.sent[-1]).sequence
    link.send_setpoints(1095, SIX)
    bus.push(*codec.encode_command_ack(3, CommandCode.ENABLE, sequence, CommandResult.ACCEPTED, WireState.ENABLED))
    enabled_at(link, bus, 3, 0)  # the first FEEDBACK after ENABLE: the reboot's 0, not a counter of ours
    assert link.read_feedback().actuators[2].setpoint_counter == -1
    link.send_setpoints(1096, SIX)
    enabled_at(link, bus, 3, 1095)
    assert link.read_feedback().actuators[2].setpoint_counter == 1095


def test_the_reason_a_legs_frames_are_rejected_reaches_the_health_detail(link, bus):
    """Finding 8: a leg whose FEEDBACK has the wrong length is not silent but rejected."""
    greet(bus, link)
    feedback = codec.encode_feedback(2, 0, 0, WireState.DISABLED, Fault(0), 0)
    bus.push(feedback[0], feedback[1][:7])
    link.read_feedback()
    assert "leg 2's frames rejected: frame 0x182: bad data length: expected 8 bytes, got 7" in link.link_health().detail


def test_a_frame_received_ends_bus_off(link, bus):
    """Finding 7: receiving proves the controller is back on the bus, restart error frame or not."""
    bus.push(0x040, bytes(8), is_error_frame=True)  # CAN_ERR_BUSOFF
    link.read_feedback()
    assert link.link_health().bus_state is BusState.BUS_OFF
    bus.push(*codec.encode_heartbeat(1, WireState.DISABLED, 0))
    link.read_feedback()
    assert link.link_health().bus_state is BusState.ACTIVE


def test_a_bus_off_followed_by_a_frame_in_one_read_is_still_said(link, bus):
    """Found from outside: a bus-off error frame, then any frame in the same read, left
    no trace: the frame ended the bus-off before the loop looked. That read says bus-off
    (frames were lost); the next, with none, does not."""
    bus.push(0x040, bytes(8), is_error_frame=True)  # CAN_ERR_BUSOFF
    bus.push(*codec.encode_heartbeat(1, WireState.DISABLED, 0))
    link.read_feedback()
    health = link.link_health()
    assert health.bus_state is BusState.BUS_OFF and "bus-off in the last read, back on the bus since" in health.detail
    link.read_feedback()
    assert link.link_health().bus_state is BusState.ACTIVE


def test_an_emergency_stands_against_a_feedback_after_it_in_one_read(link, bus):
    """Found from outside: an EMCY (FAULT, overtemperature), then the leg's FEEDBACK in the
    same read saying ENABLED, left the loop seeing an enabled leg with no fault."""
    bus.push(*codec.encode_emergency(2, codec.FaultCode.OVERTEMPERATURE, WireState.FAULT, Fault.OVERTEMPERATURE))
    bus.push(*codec.encode_feedback(2, 1000, 0, WireState.ENABLED, Fault(0), 0))
    two = link.read_feedback().actuators[1]
    assert two.state is ActuatorState.FAULT and two.fault_names == ("overtemperature",) and two.position_mm == 1.0
    bus.push(*codec.encode_feedback(2, 1000, 0, WireState.ENABLED, Fault(0), 0))  # a read later: its own word
    assert link.read_feedback().actuators[1].state is ActuatorState.ENABLED


def test_a_command_given_up_is_named(link, bus, clock):
    """Finding 11: the detail names the command, not its byte."""
    link.send_command(3, ActuatorCommand.LOCK)
    for _ in range(4):
        clock.t_ns += 20 * MS
        link.read_feedback()
    assert link.link_health().detail.endswith("; leg 3: command LOCK not acknowledged after 3 retries")


def test_an_actuator_that_restarts_is_named_and_a_counter_wrap_is_not_a_restart(link, bus):
    """Found from outside: a leg that restarted (a power glitch) read DISABLED with no fault
    and nothing said why; its heartbeat counter beginning again at 0 says it."""
    for counter in (250, 251, 252, 253, 254, 255, 0, 1):  # a wrap
        bus.push(*codec.encode_heartbeat(3, WireState.DISABLED, counter))
    link.read_feedback()
    assert link.node_status(3).restarts == 0 and "restarted" not in link.link_health().detail
    bus.push(*codec.encode_heartbeat(3, WireState.DISABLED, 0))
    assert link.read_feedback().actuators[2].restarts == 1  # the loop's faults say it (test_supervisor.py)
    assert link.node_status(3).restarts == 1
    assert ("leg 3 restarted (its heartbeat counter began again at 0 after 1): a power or watchdog reset"
            in link.link_health().detail)
    bus.push(*codec.encode_heartbeat(5, WireState.DISABLED, 40))
    bus.push(*codec.encode_heartbeat(5, WireState.INIT, 41))  # booting, its counter kept
    link.read_feedback()
    assert link.node_status(5).restarts == 1
    assert "leg 5 restarted (it reports INIT, booting, after DISABLED)" in link.link_health().detail


def test_two_actuators_answering_as_one_node_are_named(link, bus):
    """Two actuators set to node 2 interleave their heartbeats: the counter goes back."""
    for counter in (10, 11, 12, 13, 90, 14, 91, 15):
        bus.push(*codec.encode_heartbeat(2, WireState.DISABLED, counter))
    link.read_feedback()
    assert "leg 2's heartbeat counter went back from 91 to 15: two actuators answer as node 2?" in \
        link.link_health().detail
    assert link.node_status(2).restarts == 0


def stray_heartbeat(node: int, protocol_version: int = codec.PROTOCOL_VERSION) -> tuple[int, bytes]:
    """Our actuator's HEARTBEAT, as one set to node id ``node`` (no leg's) sends it."""
    _, payload = codec.encode_heartbeat(1, WireState.DISABLED, 7, protocol_version)
    return codec.NodeFrameBase.HEARTBEAT + node, payload


def test_an_actuator_set_to_a_node_id_no_leg_has_is_named_beside_the_silent_leg(link, bus, clock):
    """Found from outside: an actuator whose node id was mis-set (9 for 3) read as a silent
    leg 3 and a counter of undecodable frames; nothing pointed at the cause."""
    for leg in (1, 2, 4, 5, 6):
        bus.push(*codec.encode_heartbeat(leg, WireState.DISABLED, 1))
    bus.push(*stray_heartbeat(9))
    link.read_feedback()
    assert link.link_health().detail == ("silent legs: 3; an actuator answers as node 9 (its heartbeat, id 0x709), "
                                         "which is no leg: set its node id to the silent leg's (1–6, one each)")
    clock.t_ns = int(LinkConfig().heartbeat_timeout_s * 1e9) + 1  # it has gone quiet since: not named any longer
    assert "node 9" not in link.link_health().detail


@pytest.mark.parametrize("frame", [stray_heartbeat(9, codec.PROTOCOL_VERSION + 1), (0x709, b"\x05"), (0x785, bytes(8)),
                                   stray_heartbeat(0x7F)[:1] + (b"\x00" * 3,)], ids=["other protocol", "other payload",
                                                                                     "not a heartbeat id", "bad dlc"])
def test_a_frame_that_is_not_our_heartbeat_from_another_node_is_not_named(link, bus, frame):
    """Another device on the bus (a CANopen node's heartbeat) is no mis-set actuator."""
    bus.push(*frame)
    link.read_feedback()
    assert link.link_health().detail.startswith("silent legs: 1, 2, 3, 4, 5, 6")
    assert "answers as node" not in link.link_health().detail
