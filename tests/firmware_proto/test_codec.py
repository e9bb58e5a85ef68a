"""Codec rules beyond the bit layouts: CRC, rejection reasons, counters, encoder range checks."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_proto import codec
from firmware_proto.codec import FrameError, FrameErrorReason
from firmware_proto.generate import PROTOCOL_MD
from hexactl.adapters.can.bus_monitor import crc8_sae_j1850 as bitwise_crc8

from .frames import MESSAGES, strategy_for

PROTECTED = [m for m in MESSAGES if "Crc" in m.signal_tree]
STRICT_LENGTH = [m for m in MESSAGES if m.name != "ESTOP"]
FRAMES = pytest.mark.parametrize("dbc_message", MESSAGES, ids=lambda m: m.name)


def _reason(can_id, payload):
    with pytest.raises(FrameError) as error:
        codec.decode(can_id, payload)
    assert error.value.can_id == can_id
    return error.value.reason


def test_crc8_check_value():
    assert codec.crc8(b"123456789") == 0x4B
    assert codec.crc8(b"") == 0x00


@given(st.binary(max_size=64))
def test_table_driven_crc_equals_bitwise_crc(data):
    assert codec.crc8(data) == bitwise_crc8(data)


@given(st.integers(0, 0x7FF), st.binary(max_size=63))
def test_frame_crc_covers_the_id_low_byte_first(can_id, body):
    assert codec.frame_crc(can_id, body) == bitwise_crc8(bytes((can_id & 0xFF, can_id >> 8)) + body)


def test_every_set_point_path_and_command_frame_is_protected():
    assert {m.name for m in PROTECTED} == {"SETPOINT_ALL_FD", "SETPOINT_12", "SETPOINT_34", "SETPOINT_56", "SYNC"} | {
        f"CMD_{n}" for n in codec.NODE_IDS}
    assert all(m.signals[-1].name == "Crc" and m.signals[-1].start == 8 * (m.length - 1) for m in PROTECTED)


@pytest.mark.parametrize("dbc_message", PROTECTED, ids=lambda m: m.name)
@given(data=st.data())
def test_any_single_bit_error_is_a_bad_crc(dbc_message, data):
    can_id, payload = codec.encode(data.draw(strategy_for(dbc_message)))
    bit = data.draw(st.integers(0, 8 * len(payload) - 1))
    corrupted = bytearray(payload)
    corrupted[bit // 8] ^= 1 << (bit % 8)

    assert _reason(can_id, bytes(corrupted)) is FrameErrorReason.BAD_CRC


@given(st.sampled_from(codec.NODE_IDS), st.sampled_from(codec.NODE_IDS), st.sampled_from(codec.CommandCode),
       st.integers(0, 255))
def test_a_command_is_only_valid_for_its_addressee(node, other, command, sequence):
    can_id, payload = codec.encode_command(node, command, sequence)
    if other != node:
        assert _reason(codec.NodeFrameBase.CMD + other, payload) is FrameErrorReason.BAD_CRC


def test_a_set_point_frame_is_only_valid_under_its_own_id():
    _can_id, payload = codec.encode_setpoint_frame(1, 7, (1000, 2000))
    assert _reason(codec.FrameId.SETPOINT_34, payload) is FrameErrorReason.BAD_CRC


@pytest.mark.parametrize("dbc_message", STRICT_LENGTH, ids=lambda m: m.name)
@given(data=st.data())
def test_a_wrong_length_is_a_bad_dlc(dbc_message, data):
    can_id, payload = codec.encode(data.draw(strategy_for(dbc_message)))
    length = data.draw(st.integers(0, 64).filter(lambda n: n != dbc_message.length))
    wrong = (payload * 64)[:length]

    assert _reason(can_id, wrong) is FrameErrorReason.BAD_DLC


@given(st.integers(0, 0x7FF).filter(lambda can_id: can_id not in {m.frame_id for m in MESSAGES}), st.binary(max_size=8))
def test_an_id_outside_the_protocol_is_unknown(can_id, payload):
    assert _reason(can_id, payload) is FrameErrorReason.UNKNOWN_ID


@pytest.mark.parametrize(
    "decoder, can_id",
    [
        (codec.decode_feedback, codec.NodeFrameBase.FEEDBACK + 7),
        (codec.decode_feedback, codec.NodeFrameBase.HEARTBEAT + 1),
        (codec.decode_setpoint_frame, codec.FrameId.SYNC),
        (codec.decode_sync, codec.FrameId.SETPOINT_12),
        (codec.decode_command, codec.NodeFrameBase.CMD),
        (codec.decode_estop, 0x001),
    ],
)
def test_a_decoder_refuses_another_frame(decoder, can_id):
    with pytest.raises(FrameError) as error:
        decoder(can_id, bytes(8))
    assert error.value.reason is FrameErrorReason.UNKNOWN_ID


def test_a_value_outside_its_table_is_a_bad_value():
    can_id, payload = codec.encode_feedback(2, 0, 0, codec.ActuatorState.ENABLED, codec.Fault(0), 0)
    state_7 = bytearray(payload)
    state_7[5] = (state_7[5] & 0xF0) | 7
    assert _reason(can_id, bytes(state_7)) is FrameErrorReason.BAD_VALUE


@given(st.binary(max_size=64))
def test_an_estop_is_never_rejected(payload):
    assert isinstance(codec.decode(codec.FrameId.ESTOP, payload), codec.EStop)


@FRAMES
@given(data=st.data())
def test_decode_undoes_encode(dbc_message, data):
    message = data.draw(strategy_for(dbc_message))
    can_id, payload = codec.encode(message)
    assert (can_id, len(payload)) == (dbc_message.frame_id, dbc_message.length)
    assert codec.decode(can_id, payload) == message


def test_one_cycle_is_three_set_point_frames_then_sync():
    positions = (0, 1, -1, codec.STROKE_MAX_UM, codec.SETPOINT_MAX_UM, codec.SETPOINT_MIN_UM)
    frames = codec.encode_setpoints(200, positions)

    assert [can_id for can_id, _ in frames] == [0x021, 0x022, 0x023, 0x02F]
    decoded = [codec.decode(*frame) for frame in frames]
    assert decoded[:3] == [
        codec.SetpointFrame(1, 200, positions[0:2]),
        codec.SetpointFrame(3, 200, positions[2:4]),
        codec.SetpointFrame(5, 200, positions[4:6]),
    ]
    assert decoded[3] == codec.Sync(200)


def test_feedback_velocity_is_rounded_to_its_resolution():
    can_id, payload = codec.encode_feedback(1, 0, 123_456, codec.ActuatorState.ENABLED, codec.Fault(0), 0)
    assert codec.decode_feedback(can_id, payload).velocity_um_s == 123_500


@pytest.mark.parametrize(
    "encode",
    [
        lambda: codec.encode_setpoints(0, [0, 0, 0, 0, 0, codec.SETPOINT_MAX_UM + 1]),
        lambda: codec.encode_setpoints(0, [codec.SETPOINT_MIN_UM - 1, 0, 0, 0, 0, 0]),
        lambda: codec.encode_setpoints(256, [0] * 6),
        lambda: codec.encode_setpoints(-1, [0] * 6),
        lambda: codec.encode_setpoints(0, [0] * 5),
        lambda: codec.encode_setpoints_fd(0, [0] * 7),
        lambda: codec.encode_setpoints_fd(256, [0] * 6),
        lambda: codec.encode_setpoints_fd(0, [0, 0, 0, 0, 0, codec.SETPOINT_MAX_UM + 1]),
        lambda: codec.encode_setpoints_fd(0, [codec.SETPOINT_MIN_UM - 1, 0, 0, 0, 0, 0]),
        lambda: codec.encode_setpoint_frame(2, 0, (0, 0)),
        lambda: codec.encode_sync(256),
        lambda: codec.encode_estop(9),
        lambda: codec.encode_feedback(0, 0, 0, codec.ActuatorState.ENABLED, 0, 0),
        lambda: codec.encode_feedback(7, 0, 0, codec.ActuatorState.ENABLED, 0, 0),
        lambda: codec.encode_feedback(1, 0, codec.VELOCITY_MAX_UM_S + 100, codec.ActuatorState.ENABLED, 0, 0),
        lambda: codec.encode_feedback(1, 0, 0, 6, 0, 0),
        lambda: codec.encode_feedback(1, 0, 0, codec.ActuatorState.ENABLED, 0x1000, 0),
        lambda: codec.encode_feedback(1, codec.SETPOINT_MAX_UM + 1, 0, codec.ActuatorState.ENABLED, 0, 0),
        lambda: codec.encode_feedback(1, 0, 0, codec.ActuatorState.ENABLED, 0, 256),
        lambda: codec.encode_command(1, 0, 0),
        lambda: codec.encode_command(1, codec.CommandCode.ENABLE, 0, 400, 5),
        lambda: codec.encode_command(1, codec.CommandCode.ENABLE, 0, codec.LoopRate.HZ_500, 256),
        lambda: codec.encode_command(1, codec.CommandCode.ENABLE, 256),
        lambda: codec.encode_command_ack(1, codec.CommandCode.ENABLE, 0, 4, codec.ActuatorState.ENABLED),
        lambda: codec.encode_command_ack(1, codec.CommandCode.ENABLE, 256, codec.CommandResult.ACCEPTED,
                                         codec.ActuatorState.ENABLED),
        lambda: codec.encode_emergency(1, 13, codec.ActuatorState.FAULT, 0),
        lambda: codec.encode_emergency(1, codec.FaultCode.COMM_TIMEOUT, codec.ActuatorState.FAULT, 0x1000),
        lambda: codec.encode_heartbeat(1, codec.ActuatorState.DISABLED, 0, rejected_frames=256),
        lambda: codec.encode_heartbeat(1, codec.ActuatorState.DISABLED, 256),
        lambda: codec.encode_heartbeat(1, codec.ActuatorState.DISABLED, 0, protocol_version=256),
    ],
)
def test_a_value_that_does_not_fit_raises(encode):
    with pytest.raises(ValueError):
        encode()


@pytest.mark.parametrize(
    "counter, last, window, fresh",
    [
        (1, 0, 5, True),
        (5, 0, 5, True),
        (6, 0, 5, False),  # gap longer than the watchdog
        (0, 0, 5, False),  # repeat
        (255, 0, 5, False),  # one behind: replay
        (0, 255, 5, True),  # wrap-around
        (4, 255, 5, True),
        (5, 255, 5, False),
        (100, 0, 100, True),
        (156, 0, 100, False),
    ],
)
def test_counter_freshness(counter, last, window, fresh):
    assert codec.is_fresh_counter(counter, last, window) is fresh


@pytest.mark.parametrize("loop_rate", [codec.LoopRate.HZ_250, codec.LoopRate.HZ_500, codec.LoopRate.HZ_1000])
def test_feedback_is_250_hz_per_actuator_and_spread_over_the_cycles(loop_rate):
    divisor = loop_rate // codec.FEEDBACK_RATE_HZ
    senders = [[n for n in codec.NODE_IDS if codec.feedback_due(n, counter, loop_rate)] for counter in range(256)]

    for node in codec.NODE_IDS:
        assert sum(node in cycle for cycle in senders) == 256 // divisor
    assert max(map(len, senders)) - min(map(len, senders)) <= 1



def test_the_whole_frame_test_vectors_in_protocol_md_are_the_codecs() -> None:
    """A firmware author checks a CRC implementation against PROTOCOL.md's whole frames
    (identifier included): they must be what the codec sends."""
    text = PROTOCOL_MD.read_text(encoding="utf-8")
    vectors = [
        codec.encode_sync(0),
        codec.encode_command(1, codec.CommandCode.ENABLE, 0, codec.LoopRate.HZ_500, 5),
        codec.encode_setpoint_frame(1, 7, [1000, -1000]),
    ]
    for can_id, payload in vectors:
        assert f"| `0x{can_id:03X}` | `{payload.hex(' ')}` |" in text, (hex(can_id), payload.hex(" "))
