"""Codec speed on the control loop's hot path.

Timed only with ``--benchmark-enable`` (the suite runs each benchmark once, untimed).
"""

from firmware_proto import codec

POSITIONS_UM = (650_000, 651_234, 649_876, 700_001, 600_999, 655_555)


def test_encode_one_cycle_of_setpoints(benchmark):
    frames = benchmark(codec.encode_setpoints, 42, POSITIONS_UM)
    assert [can_id for can_id, _ in frames] == [0x021, 0x022, 0x023, 0x02F]


def test_decode_one_feedback_frame(benchmark):
    can_id, payload = codec.encode_feedback(
        3, 651_234, -123_400, codec.ActuatorState.ENABLED, codec.Fault(0), 42
    )
    feedback = benchmark(codec.decode_feedback, can_id, payload)
    assert feedback.position_um == 651_234
