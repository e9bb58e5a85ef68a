"""Test oracle for the protocol: per DBC message, a strategy of valid codec messages and their DBC signal values.

Everything here is written against the DBC and a bitwise CRC (the bus monitor's, which
shares nothing with the codec: :mod:`hexactl.adapters.can.bus_monitor`), independently of
the codec's bit operations and table-driven CRC.
"""

from __future__ import annotations

from typing import Any

from cantools.database.can import Message as DbcMessage
from hypothesis import strategies as st

from firmware_proto import codec, load_database
from hexactl.adapters.can.bus_monitor import frame_crc as bitwise_frame_crc

DB = load_database()
MESSAGES = DB.messages

u8 = st.integers(0, 0xFF)
positions_um = st.integers(codec.SETPOINT_MIN_UM, codec.SETPOINT_MAX_UM)
states = st.sampled_from(codec.ActuatorState)
commands = st.sampled_from(codec.CommandCode)
fault_words = st.integers(0, 0xFFF).map(codec.Fault)


def with_reference_crc(can_id: int, payload: bytes) -> bytes:
    """``payload`` with its last byte replaced by the CRC over the id and the other bytes."""
    return payload[:-1] + bytes((bitwise_frame_crc(can_id, payload),))


def node_of(message: DbcMessage) -> int:
    return int(message.name.rsplit("_", 1)[1])


def strategy_for(message: DbcMessage) -> st.SearchStrategy[codec.Message]:
    """Valid codec message tuples that encode to ``message``."""
    name = message.name
    if name == "ESTOP":
        return st.builds(codec.EStop, st.sampled_from(codec.EStopReason))
    if name == "SETPOINT_ALL_FD":
        return st.builds(codec.SetpointsFd, u8, st.tuples(*[positions_um] * 6))
    if name.startswith("SETPOINT_"):
        return st.builds(codec.SetpointFrame, st.just(int(name[-2])), u8, st.tuples(positions_um, positions_um))
    if name == "SYNC":
        return st.builds(codec.Sync, u8)
    node = st.just(node_of(message))
    kind = name.rsplit("_", 1)[0]
    if kind == "EMCY":
        return st.builds(codec.Emergency, node, st.sampled_from(codec.FaultCode), states, fault_words)
    if kind == "CMD":
        return st.builds(codec.Command, node, commands, u8, st.sampled_from(codec.LoopRate), u8)
    if kind == "FEEDBACK":
        velocities = st.integers(-(1 << 15), (1 << 15) - 1).map(lambda raw: raw * 100)
        return st.builds(codec.Feedback, node, positions_um, velocities, states, fault_words, u8)
    if kind == "CMD_ACK":
        return st.builds(codec.CommandAck, node, commands, u8, st.sampled_from(codec.CommandResult), states)
    if kind == "HEARTBEAT":
        return st.builds(codec.Heartbeat, node, states, u8, u8, u8)
    raise AssertionError(f"no strategy for {name}")


def fault_signal_name(fault: codec.Fault) -> str:
    return "Fault" + fault.name.title().replace("_", "")


def dbc_fault_names() -> dict[int, str]:
    """Bit → name of every fault bit as the DBC defines it: FaultCode n + 1 names bit n
    (PROTOCOL.md section 9)."""
    choices = DB.get_message_by_name("EMCY_1").get_signal_by_name("FaultCode").choices
    return {code - 1: str(name) for code, name in choices.items() if code}


def _fault_signals(faults: int) -> dict[str, int]:
    return {fault_signal_name(fault): int(bool(faults & fault)) for fault in codec.Fault}


def _signals_without_crc(message: codec.Message) -> dict[str, Any]:
    match message:
        case codec.EStop(reason):
            return {"Reason": reason}
        case codec.SetpointFrame(first_node, counter, (position_a, position_b)):
            return {f"Setpoint{first_node}": position_a, f"Setpoint{first_node + 1}": position_b, "Counter": counter}
        case codec.SetpointsFd(counter, positions):
            return {**{f"Setpoint{n}": p for n, p in enumerate(positions, 1)}, "Counter": counter}
        case codec.Sync(counter):
            return {"Counter": counter}
        case codec.Emergency(_node, fault_code, state, faults):
            return {"FaultCode": fault_code, "State": state, **_fault_signals(faults)}
        case codec.Command(_node, command, sequence, loop_rate, watchdog_cycles):
            return {"Command": command, "Sequence": sequence, "LoopRate": loop_rate, "WatchdogCycles": watchdog_cycles}
        case codec.Feedback(_node, position, velocity, state, faults, setpoint_counter):
            return {"Position": position, "Velocity": velocity, "State": state, **_fault_signals(faults),
                    "SetpointCounter": setpoint_counter}
        case codec.CommandAck(_node, command, sequence, result, state):
            return {"Command": command, "Sequence": sequence, "Result": result, "State": state}
        case codec.Heartbeat(_node, state, counter, protocol_version, rejected_frames):
            return {"State": state, "Counter": counter, "ProtocolVersion": protocol_version,
                    "RejectedFrames": rejected_frames}
    raise AssertionError(f"unknown message {message!r}")


def signals_of(dbc_message: DbcMessage, message: codec.Message) -> dict[str, int]:
    """DBC signal values (plain ints, physical units) of a codec message, its CRC included."""
    signals = {name: int(value) for name, value in _signals_without_crc(message).items()}
    if "Crc" in dbc_message.signal_tree:
        without_crc = dbc_message.encode({**signals, "Crc": 0}, strict=True)
        signals["Crc"] = with_reference_crc(dbc_message.frame_id, without_crc)[-1]
    return signals
