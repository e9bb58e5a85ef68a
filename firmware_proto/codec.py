"""Fast encoder and decoder for the hexapod actuator CAN protocol.

The frame layouts mirror ``hexapod.dbc``, the protocol's source of truth (see
``PROTOCOL.md``); the test-suite checks every frame against cantools and the
generated C code. The module is meant for the control loop: layouts are fixed
integer bit operations, nothing is parsed at run time and cantools is not imported.

Units: positions in micrometres (µm) in the actuator's sensor frame, velocities
in µm/s, payload lengths in bytes.

Encoders validate every field and return a :data:`CanFrame` ``(can_id, payload)``
ready for ``can.Message(arbitration_id=can_id, data=payload, is_extended_id=False)``;
they raise :class:`ValueError` for a value that does not fit its field.
Decoders take the identifier and payload of a received frame and return one of
the message tuples below, or raise :class:`FrameError` for a frame the receiver
must ignore.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from enum import Enum, IntEnum, IntFlag
from typing import NamedTuple, TypeAlias

PROTOCOL_VERSION = 1
"""Carried by every HEARTBEAT; the controller enables no actuator that reports another version."""

NODE_IDS = range(1, 7)

SETPOINT_MIN_UM = -(1 << 23)
SETPOINT_MAX_UM = (1 << 23) - 1
"""Encodable set-point and position range: about ±8388 mm, far outside the stroke so that an
out-of-stroke set-point reaches the actuator intact and is refused there instead of wrapping."""

STROKE_MIN_UM = 0
STROKE_MAX_UM = 1_300_000
"""Sensor stroke; the actuators' default soft limits."""

VELOCITY_RESOLUTION_UM_S = 100
VELOCITY_MIN_UM_S = -(1 << 15) * VELOCITY_RESOLUTION_UM_S
VELOCITY_MAX_UM_S = ((1 << 15) - 1) * VELOCITY_RESOLUTION_UM_S

FEEDBACK_RATE_HZ = 250
"""Every actuator sends FEEDBACK at this rate whatever the loop rate."""

WATCHDOG_CYCLES_MIN = 3
WATCHDOG_CYCLES_MAX = 100
WATCHDOG_CYCLES_DEFAULT = 5


class FrameId(IntEnum):
    """Identifiers of the frames that exist once on the bus (lower wins arbitration)."""

    ESTOP = 0x000
    SETPOINT_ALL_FD = 0x020
    SETPOINT_12 = 0x021
    SETPOINT_34 = 0x022
    SETPOINT_56 = 0x023
    SYNC = 0x02F


class NodeFrameBase(IntEnum):
    """Per-actuator frames: the identifier is the base plus the node id (1..6)."""

    EMCY = 0x080
    CMD = 0x100
    FEEDBACK = 0x180
    CMD_ACK = 0x200
    HEARTBEAT = 0x700


class ActuatorState(IntEnum):
    """Actuator state machine (see PROTOCOL.md for the transition table)."""

    INIT = 0
    DISABLED = 1
    ENABLED = 2
    LOCKED = 3
    FAULT = 4
    ESTOP = 5


class CommandCode(IntEnum):
    ENABLE = 1
    DISABLE = 2
    CLEAR_FAULT = 3
    LOCK = 4
    UNLOCK = 5


class CommandResult(IntEnum):
    ACCEPTED = 0
    REJECTED_STATE = 1
    REJECTED_FAULT_ACTIVE = 2
    REJECTED_ARGUMENT = 3


class LoopRate(IntEnum):
    """Control loop rate in Hz, sent with ENABLE; NOT_SET in every other command."""

    NOT_SET = 0
    HZ_250 = 250
    HZ_500 = 500
    HZ_1000 = 1000


class EStopReason(IntEnum):
    OPERATOR = 0
    ACTUATOR_FAULT = 1
    FEEDBACK_LOST = 2
    CONTROLLER_FAULT = 3
    SAFETY_CHAIN = 4


class Fault(IntFlag):
    """Latched fault bits of FEEDBACK and EMCY; bit n is FaultCode n + 1."""

    COMM_TIMEOUT = 1 << 0
    ESTOP = 1 << 1
    SETPOINT_RANGE = 1 << 2
    FOLLOWING_ERROR = 1 << 3
    OVERSPEED = 1 << 4
    OVERCURRENT = 1 << 5
    OVERTEMPERATURE = 1 << 6
    SENSOR = 1 << 7
    SUPPLY = 1 << 8
    BRAKE = 1 << 9
    LIMIT_SWITCH = 1 << 10
    INTERNAL = 1 << 11


class FaultCode(IntEnum):
    """The fault that triggered an EMCY; NONE announces that all faults were cleared."""

    NONE = 0
    COMM_TIMEOUT = 1
    ESTOP = 2
    SETPOINT_RANGE = 3
    FOLLOWING_ERROR = 4
    OVERSPEED = 5
    OVERCURRENT = 6
    OVERTEMPERATURE = 7
    SENSOR = 8
    SUPPLY = 9
    BRAKE = 10
    LIMIT_SWITCH = 11
    INTERNAL = 12

    @property
    def flag(self) -> Fault:
        """The :class:`Fault` bit this code latches (empty for NONE)."""
        return Fault(1 << (self - 1)) if self else Fault(0)


class FrameErrorReason(Enum):
    UNKNOWN_ID = "unknown frame id"
    BAD_DLC = "bad data length"
    BAD_CRC = "bad CRC"
    BAD_VALUE = "value outside its defined set"


class FrameError(ValueError):
    """A received frame that the receiver must ignore (and count as rejected).

    :ivar reason: what is wrong with the frame
    :ivar can_id: the frame's identifier
    """

    def __init__(self, reason: FrameErrorReason, can_id: int, detail: str) -> None:
        super().__init__(f"frame 0x{can_id:03X}: {reason.value}: {detail}")
        self.reason = reason
        self.can_id = can_id


CanFrame: TypeAlias = tuple[int, bytes]
"""``(can_id, payload)`` of one classic or FD frame with an 11-bit identifier."""


class EStop(NamedTuple):
    reason: EStopReason | None
    """None when the payload carries no known reason; the frame is an e-stop all the same."""


class SetpointFrame(NamedTuple):
    """Classic profile: the set-points of nodes ``first_node`` and ``first_node + 1``."""

    first_node: int
    counter: int
    positions_um: tuple[int, int]


class SetpointsFd(NamedTuple):
    """CAN FD profile: the set-points of nodes 1..6."""

    counter: int
    positions_um: tuple[int, int, int, int, int, int]


class Sync(NamedTuple):
    counter: int


class Emergency(NamedTuple):
    node: int
    fault_code: FaultCode
    state: ActuatorState
    faults: Fault


class Command(NamedTuple):
    node: int
    command: CommandCode
    sequence: int
    loop_rate: LoopRate
    watchdog_cycles: int


class Feedback(NamedTuple):
    node: int
    position_um: int
    velocity_um_s: int
    state: ActuatorState
    faults: Fault
    setpoint_counter: int


class CommandAck(NamedTuple):
    node: int
    command: CommandCode
    sequence: int
    result: CommandResult
    state: ActuatorState


class Heartbeat(NamedTuple):
    node: int
    state: ActuatorState
    counter: int
    protocol_version: int
    rejected_frames: int


Message: TypeAlias = (
    EStop | SetpointFrame | SetpointsFd | Sync | Emergency | Command | Feedback | CommandAck | Heartbeat
)


# --- CRC-8/SAE-J1850: poly 0x1D, init 0xFF, not reflected, xorout 0xFF, check 0x4B -----------------

CRC8_POLY = 0x1D
CRC8_INIT = 0xFF
CRC8_XOR_OUT = 0xFF


def _crc8_byte_table() -> bytes:
    table = bytearray(256)
    for index in range(256):
        crc = index
        for _ in range(8):
            crc = ((crc << 1) ^ CRC8_POLY if crc & 0x80 else crc << 1) & 0xFF
        table[index] = crc
    return bytes(table)


_CRC8_TABLE = _crc8_byte_table()


def _crc8_update(crc: int, data: bytes) -> int:
    table = _CRC8_TABLE
    for byte in data:
        crc = table[crc ^ byte]
    return crc


def crc8(data: bytes) -> int:
    """CRC-8/SAE-J1850 of ``data`` (``crc8(b"123456789") == 0x4B``)."""
    return _crc8_update(CRC8_INIT, data) ^ CRC8_XOR_OUT


def _frame_crc(can_id: int, body: int, length: int) -> int:
    # The identifier is part of the CRC (as two bytes, low first) so that a payload that is valid
    # for one frame, e.g. CMD_3, is never accepted under another identifier, e.g. CMD_4.
    return _crc8_update(CRC8_INIT, (can_id | body << 16).to_bytes(length + 2, "little")) ^ CRC8_XOR_OUT


def frame_crc(can_id: int, body: bytes) -> int:
    """CRC byte of a protected frame (SETPOINT_*, SYNC, CMD_n).

    :param can_id: 11-bit identifier, fed to the CRC as two bytes, low byte first
    :param body: the payload bytes that precede the CRC byte
    """
    return _frame_crc(can_id, int.from_bytes(body, "little"), len(body))


# --- Counter and schedule rules -------------------------------------------------------------------


def is_fresh_counter(counter: int, last_counter: int, window: int) -> bool:
    """Whether a set-point cycle ``counter`` may be applied after ``last_counter``.

    Counters run modulo 256. A counter equal to the last one is stale (a repeat), one that is
    behind it or more than ``window`` (the watchdog cycles, at most 100) ahead is a replay or comes
    after a gap that the watchdog has already turned into a fault.
    """
    return 1 <= (counter - last_counter) & 0xFF <= window


def feedback_due(node: int, counter: int, loop_rate: LoopRate) -> bool:
    """Whether actuator ``node`` answers the SYNC with ``counter`` with a FEEDBACK frame.

    Feedback runs at :data:`FEEDBACK_RATE_HZ`; at higher loop rates the six actuators are spread
    over the cycles so that every cycle carries about the same number of feedback frames.

    :raises ZeroDivisionError: for ``LoopRate.NOT_SET``
    """
    divisor = loop_rate // FEEDBACK_RATE_HZ
    return counter % divisor == (node - 1) % divisor


# --- Encoding -------------------------------------------------------------------------------------

_U8_MAX = 0xFF
_MASK24 = 0xFFFFFF
_MASK12 = 0xFFF


def _members(enum: type[IntEnum]) -> dict[int, IntEnum]:
    return {member.value: member for member in enum}


_STATES = _members(ActuatorState)
_COMMANDS = _members(CommandCode)
_RESULTS = _members(CommandResult)
_LOOP_RATES = _members(LoopRate)
_ESTOP_REASONS = _members(EStopReason)
_FAULT_CODES = _members(FaultCode)
# Built once so that decoding a fault word is an index, not an IntFlag construction.
_FAULTS = tuple(Fault(raw) for raw in range(_MASK12 + 1))

_SETPOINT_FRAME_IDS = {1: FrameId.SETPOINT_12, 3: FrameId.SETPOINT_34, 5: FrameId.SETPOINT_56}
_SETPOINT_FRAME_FIRST_NODE = {can_id: node for node, can_id in _SETPOINT_FRAME_IDS.items()}


def _check_range(name: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise ValueError(f"{name} = {value!r} outside {low}..{high}")


def _check_member(name: str, value: int, members: dict[int, IntEnum]) -> None:
    if value not in members:
        raise ValueError(f"{name} = {value!r} is not one of {sorted(members)}")


def _check_node(node: int) -> None:
    _check_range("node", node, NODE_IDS.start, NODE_IDS.stop - 1)


def _pack_setpoint_frame(can_id: int, counter: int, position_a_um: int, position_b_um: int) -> CanFrame:
    _check_range("counter", counter, 0, _U8_MAX)
    _check_range("position_um", position_a_um, SETPOINT_MIN_UM, SETPOINT_MAX_UM)
    _check_range("position_um", position_b_um, SETPOINT_MIN_UM, SETPOINT_MAX_UM)
    body = (position_a_um & _MASK24) | (position_b_um & _MASK24) << 24 | counter << 48
    return can_id, (body | _frame_crc(can_id, body, 7) << 56).to_bytes(8, "little")


def encode_setpoints(counter: int, positions_um: Sequence[int]) -> tuple[CanFrame, CanFrame, CanFrame, CanFrame]:
    """Encode one cycle of the classic profile: SETPOINT_12, SETPOINT_34, SETPOINT_56, then SYNC.

    Send the frames in this order; the actuators apply the set-points at the SYNC.

    :param counter: cycle counter 0..255, one more (modulo 256) than the previous cycle's
    :param positions_um: set-points of nodes 1..6 in µm; values outside the stroke are encoded as
        given (the actuator refuses them), values outside ±2**23 µm raise
    :raises ValueError: if a value does not fit its field or there are not six positions
    """
    p1, p2, p3, p4, p5, p6 = positions_um
    return (
        _pack_setpoint_frame(FrameId.SETPOINT_12, counter, p1, p2),
        _pack_setpoint_frame(FrameId.SETPOINT_34, counter, p3, p4),
        _pack_setpoint_frame(FrameId.SETPOINT_56, counter, p5, p6),
        encode_sync(counter),
    )


def encode_setpoint_frame(first_node: int, counter: int, positions_um: Sequence[int]) -> CanFrame:
    """Encode one SETPOINT_xy frame.

    :param first_node: 1, 3 or 5: the frame carries nodes ``first_node`` and ``first_node + 1``
    :param counter: cycle counter 0..255
    :param positions_um: the two set-points in µm
    :raises ValueError: for another ``first_node``, a value that does not fit or not two positions
    """
    can_id = _SETPOINT_FRAME_IDS.get(first_node)
    if can_id is None:
        raise ValueError(f"first_node = {first_node!r} is not one of 1, 3, 5")
    position_a_um, position_b_um = positions_um
    return _pack_setpoint_frame(can_id, counter, position_a_um, position_b_um)


def encode_setpoints_fd(counter: int, positions_um: Sequence[int]) -> CanFrame:
    """Encode SETPOINT_ALL_FD, the CAN FD profile's whole cycle (applied at reception, no SYNC).

    Send it as an FD frame with bit-rate switch (``is_fd=True, bitrate_switch=True``).

    :param counter: cycle counter 0..255
    :param positions_um: set-points of nodes 1..6 in µm
    :raises ValueError: if a value does not fit its field or there are not six positions
    """
    _check_range("counter", counter, 0, _U8_MAX)
    if len(positions_um) != len(NODE_IDS):
        raise ValueError(f"expected {len(NODE_IDS)} positions, got {len(positions_um)}")
    body = counter << 144
    for index, position_um in enumerate(positions_um):
        _check_range("position_um", position_um, SETPOINT_MIN_UM, SETPOINT_MAX_UM)
        body |= (position_um & _MASK24) << (24 * index)
    can_id = FrameId.SETPOINT_ALL_FD
    return can_id, (body | _frame_crc(can_id, body, 19) << 152).to_bytes(20, "little")


def encode_sync(counter: int) -> CanFrame:
    """Encode SYNC, which ends a classic-profile cycle.

    :param counter: cycle counter 0..255, equal to the counter of the cycle's set-point frames
    :raises ValueError: if ``counter`` is outside 0..255
    """
    _check_range("counter", counter, 0, _U8_MAX)
    can_id = FrameId.SYNC
    return can_id, bytes((counter, _frame_crc(can_id, counter, 1)))


def encode_estop(reason: EStopReason) -> CanFrame:
    """Encode ESTOP, the highest-priority frame.

    :raises ValueError: if ``reason`` is not an :class:`EStopReason`
    """
    _check_member("reason", reason, _ESTOP_REASONS)
    return FrameId.ESTOP, bytes((reason,))


def encode_emergency(node: int, fault_code: FaultCode, state: ActuatorState, faults: Fault) -> CanFrame:
    """Encode EMCY_n.

    :param node: sending actuator 1..6
    :param fault_code: the fault that triggered the message, NONE when all faults were cleared
    :param state: actuator state after the event
    :param faults: all latched faults
    :raises ValueError: if a value does not fit its field
    """
    _check_node(node)
    _check_member("fault_code", fault_code, _FAULT_CODES)
    _check_member("state", state, _STATES)
    _check_range("faults", faults, 0, _MASK12)
    body = fault_code | state << 8 | faults << 16
    return NodeFrameBase.EMCY + node, body.to_bytes(4, "little")


def encode_command(
    node: int,
    command: CommandCode,
    sequence: int,
    loop_rate: LoopRate = LoopRate.NOT_SET,
    watchdog_cycles: int = 0,
) -> CanFrame:
    """Encode CMD_n.

    :param node: addressed actuator 1..6
    :param command: requested transition
    :param sequence: 0..255, new for every command and kept for its retries
    :param loop_rate: ENABLE only: the control loop rate
    :param watchdog_cycles: ENABLE only: cycles without a valid set-point before COMM_TIMEOUT;
        the actuator accepts 3..100 (:data:`WATCHDOG_CYCLES_MIN`..:data:`WATCHDOG_CYCLES_MAX`)
    :raises ValueError: if a value does not fit its field
    """
    _check_node(node)
    _check_member("command", command, _COMMANDS)
    _check_range("sequence", sequence, 0, _U8_MAX)
    _check_member("loop_rate", loop_rate, _LOOP_RATES)
    _check_range("watchdog_cycles", watchdog_cycles, 0, _U8_MAX)
    can_id = NodeFrameBase.CMD + node
    body = command | sequence << 8 | loop_rate << 16 | watchdog_cycles << 32
    return can_id, (body | _frame_crc(can_id, body, 5) << 40).to_bytes(6, "little")


def encode_feedback(
    node: int,
    position_um: int,
    velocity_um_s: int,
    state: ActuatorState,
    faults: Fault,
    setpoint_counter: int,
) -> CanFrame:
    """Encode FEEDBACK_n.

    :param node: sending actuator 1..6
    :param position_um: measured position in µm
    :param velocity_um_s: measured velocity in µm/s, rounded (half to even) to 100 µm/s
    :param state: actuator state
    :param faults: latched faults
    :param setpoint_counter: counter of the last applied set-point
    :raises ValueError: if a value does not fit its field
    """
    _check_node(node)
    _check_range("position_um", position_um, SETPOINT_MIN_UM, SETPOINT_MAX_UM)
    velocity_raw = round(velocity_um_s / VELOCITY_RESOLUTION_UM_S)
    _check_range("velocity_um_s", velocity_raw * VELOCITY_RESOLUTION_UM_S, VELOCITY_MIN_UM_S, VELOCITY_MAX_UM_S)
    _check_member("state", state, _STATES)
    _check_range("faults", faults, 0, _MASK12)
    _check_range("setpoint_counter", setpoint_counter, 0, _U8_MAX)
    body = (
        (position_um & _MASK24)
        | (velocity_raw & 0xFFFF) << 24
        | state << 40
        | faults << 44
        | setpoint_counter << 56
    )
    return NodeFrameBase.FEEDBACK + node, body.to_bytes(8, "little")


def encode_command_ack(
    node: int, command: CommandCode, sequence: int, result: CommandResult, state: ActuatorState
) -> CanFrame:
    """Encode CMD_ACK_n.

    :param node: sending actuator 1..6
    :param command: echo of the command
    :param sequence: echo of the command's sequence
    :param result: outcome
    :param state: actuator state after the command
    :raises ValueError: if a value does not fit its field
    """
    _check_node(node)
    _check_member("command", command, _COMMANDS)
    _check_range("sequence", sequence, 0, _U8_MAX)
    _check_member("result", result, _RESULTS)
    _check_member("state", state, _STATES)
    body = command | sequence << 8 | result << 16 | state << 24
    return NodeFrameBase.CMD_ACK + node, body.to_bytes(4, "little")


def encode_heartbeat(
    node: int,
    state: ActuatorState,
    counter: int,
    protocol_version: int = PROTOCOL_VERSION,
    rejected_frames: int = 0,
) -> CanFrame:
    """Encode HEARTBEAT_n.

    :param node: sending actuator 1..6
    :param state: actuator state
    :param counter: heartbeat counter 0..255, one more per heartbeat
    :param protocol_version: protocol version the firmware implements
    :param rejected_frames: protected frames rejected since the previous heartbeat, saturating at 255
    :raises ValueError: if a value does not fit its field
    """
    _check_node(node)
    _check_member("state", state, _STATES)
    _check_range("counter", counter, 0, _U8_MAX)
    _check_range("protocol_version", protocol_version, 0, _U8_MAX)
    _check_range("rejected_frames", rejected_frames, 0, _U8_MAX)
    body = state | counter << 8 | protocol_version << 16 | rejected_frames << 24
    return NodeFrameBase.HEARTBEAT + node, body.to_bytes(4, "little")


# --- Decoding -------------------------------------------------------------------------------------


def _body(can_id: int, payload: bytes, length: int) -> int:
    if len(payload) != length:
        raise FrameError(FrameErrorReason.BAD_DLC, can_id, f"expected {length} bytes, got {len(payload)}")
    return int.from_bytes(payload, "little")


def _protected_body(can_id: int, payload: bytes, length: int) -> int:
    """The payload without its trailing CRC byte, after checking length and CRC."""
    value = _body(can_id, payload, length)
    crc_shift = 8 * (length - 1)
    body = value & ((1 << crc_shift) - 1)
    received = value >> crc_shift
    expected = _frame_crc(can_id, body, length - 1)
    if received != expected:
        raise FrameError(FrameErrorReason.BAD_CRC, can_id, f"CRC 0x{received:02X}, expected 0x{expected:02X}")
    return body


def _member(members: dict[int, IntEnum], raw: int, can_id: int, field: str) -> IntEnum:
    member = members.get(raw)
    if member is None:
        raise FrameError(FrameErrorReason.BAD_VALUE, can_id, f"{field} = {raw}")
    return member


def _node(can_id: int, base: NodeFrameBase) -> int:
    node = can_id - base
    if node not in NODE_IDS:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, f"not a {base.name}_n frame")
    return node


def _signed24(raw: int) -> int:
    return raw - ((raw & 0x800000) << 1)


def decode_estop(can_id: int, payload: bytes) -> EStop:
    """Decode ESTOP. Never rejects a payload: an ESTOP stops the actuators whatever it carries.

    :raises FrameError: UNKNOWN_ID if ``can_id`` is not ESTOP
    """
    if can_id != FrameId.ESTOP:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, "not an ESTOP frame")
    return EStop(_ESTOP_REASONS.get(payload[0]) if len(payload) == 1 else None)


def decode_setpoint_frame(can_id: int, payload: bytes) -> SetpointFrame:
    """Decode SETPOINT_12, SETPOINT_34 or SETPOINT_56.

    The counter is returned as received; whether it is fresh is the receiver's decision
    (:func:`is_fresh_counter`).

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_CRC
    """
    first_node = _SETPOINT_FRAME_FIRST_NODE.get(can_id)
    if first_node is None:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, "not a SETPOINT_xy frame")
    body = _protected_body(can_id, payload, 8)
    return SetpointFrame(
        first_node, body >> 48, (_signed24(body & _MASK24), _signed24((body >> 24) & _MASK24))
    )


def decode_setpoints_fd(can_id: int, payload: bytes) -> SetpointsFd:
    """Decode SETPOINT_ALL_FD.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_CRC
    """
    if can_id != FrameId.SETPOINT_ALL_FD:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, "not a SETPOINT_ALL_FD frame")
    body = _protected_body(can_id, payload, 20)
    positions = tuple(_signed24((body >> shift) & _MASK24) for shift in range(0, 144, 24))
    return SetpointsFd(body >> 144, positions)


def decode_sync(can_id: int, payload: bytes) -> Sync:
    """Decode SYNC.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_CRC
    """
    if can_id != FrameId.SYNC:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, "not a SYNC frame")
    return Sync(_protected_body(can_id, payload, 2))


def decode_emergency(can_id: int, payload: bytes) -> Emergency:
    """Decode EMCY_n.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_VALUE (unknown fault code or state)
    """
    node = _node(can_id, NodeFrameBase.EMCY)
    body = _body(can_id, payload, 4)
    return Emergency(
        node,
        _member(_FAULT_CODES, body & 0xFF, can_id, "fault_code"),
        _member(_STATES, (body >> 8) & 0xF, can_id, "state"),
        _FAULTS[(body >> 16) & _MASK12],
    )


def decode_command(can_id: int, payload: bytes) -> Command:
    """Decode CMD_n. Arguments are returned as received; their validity is the actuator's decision.

    :raises FrameError: UNKNOWN_ID, BAD_DLC, BAD_CRC or BAD_VALUE (unknown command or loop rate)
    """
    node = _node(can_id, NodeFrameBase.CMD)
    body = _protected_body(can_id, payload, 6)
    return Command(
        node,
        _member(_COMMANDS, body & 0xFF, can_id, "command"),
        (body >> 8) & 0xFF,
        _member(_LOOP_RATES, (body >> 16) & 0xFFFF, can_id, "loop_rate"),
        body >> 32,
    )


def decode_feedback(can_id: int, payload: bytes) -> Feedback:
    """Decode FEEDBACK_n; the velocity is a multiple of 100 µm/s.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_VALUE (unknown state)
    """
    node = _node(can_id, NodeFrameBase.FEEDBACK)
    body = _body(can_id, payload, 8)
    velocity_raw = (body >> 24) & 0xFFFF
    return Feedback(
        node,
        _signed24(body & _MASK24),
        (velocity_raw - ((velocity_raw & 0x8000) << 1)) * VELOCITY_RESOLUTION_UM_S,
        _member(_STATES, (body >> 40) & 0xF, can_id, "state"),
        _FAULTS[(body >> 44) & _MASK12],
        body >> 56,
    )


def decode_command_ack(can_id: int, payload: bytes) -> CommandAck:
    """Decode CMD_ACK_n.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_VALUE (unknown command, result or state)
    """
    node = _node(can_id, NodeFrameBase.CMD_ACK)
    body = _body(can_id, payload, 4)
    return CommandAck(
        node,
        _member(_COMMANDS, body & 0xFF, can_id, "command"),
        (body >> 8) & 0xFF,
        _member(_RESULTS, (body >> 16) & 0xFF, can_id, "result"),
        _member(_STATES, (body >> 24) & 0xF, can_id, "state"),
    )


def decode_heartbeat(can_id: int, payload: bytes) -> Heartbeat:
    """Decode HEARTBEAT_n.

    :raises FrameError: UNKNOWN_ID, BAD_DLC or BAD_VALUE (unknown state)
    """
    node = _node(can_id, NodeFrameBase.HEARTBEAT)
    body = _body(can_id, payload, 4)
    return Heartbeat(
        node,
        _member(_STATES, body & 0xF, can_id, "state"),
        (body >> 8) & 0xFF,
        (body >> 16) & 0xFF,
        body >> 24,
    )


_NODE_DECODERS: dict[NodeFrameBase, Callable[[int, bytes], Message]] = {
    NodeFrameBase.EMCY: decode_emergency,
    NodeFrameBase.CMD: decode_command,
    NodeFrameBase.FEEDBACK: decode_feedback,
    NodeFrameBase.CMD_ACK: decode_command_ack,
    NodeFrameBase.HEARTBEAT: decode_heartbeat,
}
_DECODERS: dict[int, Callable[[int, bytes], Message]] = {
    FrameId.ESTOP: decode_estop,
    FrameId.SETPOINT_ALL_FD: decode_setpoints_fd,
    FrameId.SETPOINT_12: decode_setpoint_frame,
    FrameId.SETPOINT_34: decode_setpoint_frame,
    FrameId.SETPOINT_56: decode_setpoint_frame,
    FrameId.SYNC: decode_sync,
    **{base + node: decoder for base, decoder in _NODE_DECODERS.items() for node in NODE_IDS},
}

_ENCODERS: dict[type, Callable[..., CanFrame]] = {
    EStop: encode_estop,
    SetpointFrame: encode_setpoint_frame,
    SetpointsFd: encode_setpoints_fd,
    Sync: encode_sync,
    Emergency: encode_emergency,
    Command: encode_command,
    Feedback: encode_feedback,
    CommandAck: encode_command_ack,
    Heartbeat: encode_heartbeat,
}


def decode(can_id: int, payload: bytes) -> Message:
    """Decode any frame of the protocol.

    :param can_id: 11-bit identifier of the received frame
    :param payload: its data bytes
    :raises FrameError: UNKNOWN_ID for an identifier outside the protocol, or the frame decoder's reason
    """
    decoder = _DECODERS.get(can_id)
    if decoder is None:
        raise FrameError(FrameErrorReason.UNKNOWN_ID, can_id, "not in the protocol")
    return decoder(can_id, payload)


def encode(message: Message) -> CanFrame:
    """Encode any message tuple; ``decode(*encode(m)) == m`` for every valid message.

    :raises ValueError: if a value does not fit its field
    :raises KeyError: if ``message`` is not one of the protocol's message tuples
    """
    return _ENCODERS[type(message)](*message)
