"""Per-cycle cost of the link on a ``memory:`` and a ``virtual:`` bus (pytest-benchmark). Run
once, untimed, in the normal suite; time with
``python -m pytest tests/can/test_link_benchmark.py --benchmark-enable``.

A cycle is what the loop does every period: :meth:`send_setpoints` (four frames) and
:meth:`read_feedback`. Each round finds on the bus what a 500 Hz cycle brings on average:
three FEEDBACK frames (six actuators at 250 Hz) and one HEARTBEAT per ten cycles; putting
them there is the round's setup, not timed.
"""

from __future__ import annotations

import itertools

import can
import pytest

from firmware_proto import codec
from firmware_proto.codec import ActuatorState, Fault
from hexactl.adapters.can.link import CanActuatorLink
from hexactl.adapters.can.transport import open_bus

ROUNDS = 2000
SETPOINTS = [300.123, 310.456, 320.789, 330.012, 340.345, 350.678]
_channels = itertools.count()


def _feedback(node: int, counter: int) -> codec.CanFrame:
    return codec.encode_feedback(node, 300_000 + node, 0, ActuatorState.ENABLED, Fault(0), counter & 0xFF)


@pytest.mark.parametrize("interface", ["memory", "virtual"])
def test_send_setpoints_and_read_feedback_cycle(benchmark, interface):
    channel = f"{interface}:hexactl-bench-{next(_channels)}"
    link = CanActuatorLink.open(channel)
    actuators = open_bus(channel)
    counter = itertools.count()

    def arrive():
        cycle = next(counter)
        while actuators.recv(0.0) is not None:  # the actuators take the previous cycle's frames
            pass
        first = 1 + cycle % 2  # nodes 1, 3, 5 on even cycles, 2, 4, 6 on odd ones
        for node in (first, first + 2, first + 4):
            actuators.send(can.Message(arbitration_id=0x180 + node, data=_feedback(node, cycle)[1], is_extended_id=False))
        if cycle % 10 == 0:
            can_id, payload = codec.encode_heartbeat(1 + cycle // 10 % 6, ActuatorState.ENABLED, cycle & 0xFF)
            actuators.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
        return (cycle,), {}

    def loop_cycle(cycle):
        link.send_setpoints(cycle, SETPOINTS)
        return link.read_feedback()

    try:
        snapshot = benchmark.pedantic(loop_cycle, setup=arrive, rounds=ROUNDS if benchmark.enabled else 3)
        assert link.link_health().send_failures == 0
        assert 300.001 in snapshot.positions_mm or 300.002 in snapshot.positions_mm
        assert link.stats().undecodable_frames == 0
    finally:
        link.close()
        actuators.shutdown()
