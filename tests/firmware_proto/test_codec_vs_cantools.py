"""Every frame of the DBC, both ways: the codec against cantools."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_proto import codec

from .frames import MESSAGES, signals_of, strategy_for, with_reference_crc

by_name = pytest.mark.parametrize("dbc_message", MESSAGES, ids=lambda m: m.name)


@by_name
@given(data=st.data())
def test_codec_bytes_equal_cantools_bytes(dbc_message, data):
    message = data.draw(strategy_for(dbc_message))
    signals = signals_of(dbc_message, message)

    can_id, payload = codec.encode(message)

    assert can_id == dbc_message.frame_id
    assert payload == dbc_message.encode(signals, strict=True)


@by_name
@given(data=st.data())
def test_cantools_decodes_codec_bytes_to_the_values(dbc_message, data):
    message = data.draw(strategy_for(dbc_message))

    can_id, payload = codec.encode(message)

    assert dbc_message.decode(payload, decode_choices=False) == signals_of(dbc_message, message)
    assert codec.decode(can_id, payload) == message


@by_name
@given(data=st.data())
def test_codec_decodes_any_payload_like_cantools(dbc_message, data):
    payload = data.draw(st.binary(min_size=dbc_message.length, max_size=dbc_message.length))
    if "Crc" in dbc_message.signal_tree:
        payload = with_reference_crc(dbc_message.frame_id, payload)
    expected = dbc_message.decode(payload, decode_choices=False)
    outside_tables = [
        name for name, value in expected.items()
        if dbc_message.get_signal_by_name(name).choices and value not in dbc_message.get_signal_by_name(name).choices
    ]

    if dbc_message.name == "ESTOP":
        assert codec.decode(dbc_message.frame_id, payload).reason == (None if outside_tables else expected["Reason"])
    elif outside_tables:
        with pytest.raises(codec.FrameError) as error:
            codec.decode(dbc_message.frame_id, payload)
        assert error.value.reason is codec.FrameErrorReason.BAD_VALUE
    else:
        assert signals_of(dbc_message, codec.decode(dbc_message.frame_id, payload)) == expected
