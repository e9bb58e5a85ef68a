"""The DBC is the source of truth: the codec's constants must equal it."""

import pytest

from firmware_proto import busload, codec

from .frames import DB, fault_signal_name

ENUM_OF_SIGNAL = {
    "State": codec.ActuatorState,
    "Command": codec.CommandCode,
    "Result": codec.CommandResult,
    "LoopRate": codec.LoopRate,
    "Reason": codec.EStopReason,
    "FaultCode": codec.FaultCode,
}


def _choices(choices) -> dict[int, str]:
    return {int(value): str(name) for value, name in choices.items()}


def _members(enum) -> dict[int, str]:
    return {member.value: member.name for member in enum}


def test_nodes_are_the_controller_and_six_actuators():
    assert [node.name for node in DB.nodes] == ["CONTROLLER"] + [f"ACT{n}" for n in codec.NODE_IDS]


def test_value_tables_equal_the_codec_enums():
    assert set(DB.dbc.value_tables) == {enum.__name__ for enum in ENUM_OF_SIGNAL.values()}
    for name, table in DB.dbc.value_tables.items():
        assert _choices(table) == _members(getattr(codec, name)), name


def test_every_enumerated_signal_uses_its_codec_enum():
    enumerated = [(m, s) for m in DB.messages for s in m.signals if s.choices]
    assert enumerated
    for message, signal in enumerated:
        assert _choices(signal.choices) == _members(ENUM_OF_SIGNAL[signal.name]), f"{message.name}.{signal.name}"


@pytest.mark.parametrize("kind, first_bit", [("FEEDBACK", 44), ("EMCY", 16)])
def test_fault_bits_sit_where_the_codec_puts_them(kind, first_bit):
    for node in codec.NODE_IDS:
        message = DB.get_message_by_name(f"{kind}_{node}")
        for bit, fault in enumerate(codec.Fault):
            signal = message.get_signal_by_name(fault_signal_name(fault))
            assert (signal.start, signal.length, fault.value) == (first_bit + bit, 1, 1 << bit)


def test_fault_codes_name_the_fault_bits():
    assert codec.FaultCode.NONE.flag == codec.Fault(0)
    for code in list(codec.FaultCode)[1:]:
        assert code.flag.name == code.name


def test_frame_ids_and_names_cover_the_dbc_exactly():
    expected = {member.name: member.value for member in codec.FrameId}
    for base in codec.NodeFrameBase:
        expected |= {f"{base.name}_{node}": base + node for node in codec.NODE_IDS}
    assert {m.name: m.frame_id for m in DB.messages} == expected
    assert not any(m.is_extended_frame for m in DB.messages)


def test_per_actuator_frames_are_sent_or_received_by_their_actuator():
    for base in codec.NodeFrameBase:
        for node in codec.NODE_IDS:
            message = DB.get_message_by_frame_id(base + node)
            actuator = f"ACT{node}"
            if base is codec.NodeFrameBase.CMD:
                assert message.senders == ["CONTROLLER"]
                assert message.receivers == {actuator}
            else:
                assert message.senders == [actuator]


def test_estop_has_the_lowest_id():
    assert min(m.frame_id for m in DB.messages) == codec.FrameId.ESTOP == 0


def test_protocol_version_and_ranges_match_the_codec():
    assert DB.dbc.attributes["ProtocolVersion"].value == codec.PROTOCOL_VERSION
    setpoint = DB.get_message_by_name("SETPOINT_12").get_signal_by_name("Setpoint1")
    assert (setpoint.minimum, setpoint.maximum, setpoint.unit) == (codec.SETPOINT_MIN_UM, codec.SETPOINT_MAX_UM, "um")
    velocity = DB.get_message_by_name("FEEDBACK_1").get_signal_by_name("Velocity")
    assert (velocity.scale, velocity.minimum, velocity.maximum, velocity.unit) == (
        codec.VELOCITY_RESOLUTION_UM_S, codec.VELOCITY_MIN_UM_S, codec.VELOCITY_MAX_UM_S, "um/s")


def test_cycle_times_match_the_codec_rates():
    for message in DB.messages:
        follows_loop = busload.follows_loop_rate(DB, message)
        if message.name.startswith(("SETPOINT", "SYNC")):
            assert follows_loop and message.cycle_time == 1000 / busload.DEFAULT_LOOP_RATE_HZ, message.name
            continue
        assert not follows_loop, message.name
        if message.name.startswith("FEEDBACK"):
            assert message.cycle_time == 1000 / codec.FEEDBACK_RATE_HZ
        elif message.name.startswith("HEARTBEAT"):
            assert message.cycle_time == 100
        else:
            assert message.cycle_time is None and message.send_type == "Event", message.name


def test_only_the_fd_setpoint_frame_is_fd():
    assert [m.name for m in DB.messages if m.is_fd] == ["SETPOINT_ALL_FD"]
