"""What the stream's receiver costs per UDP datagram, the check for a second sender
included (pytest-benchmark). Run ``python -m pytest tests/stream/test_stream_receiver_benchmark.py
--benchmark-enable``; figures in BENCHMARKS.md. Without ``--benchmark-enable`` it runs once,
as a test that every datagram is taken."""

from __future__ import annotations

import time

from tests.reliability.support import wait_for
from tools.serving import HANG_S
from tests.stream.test_stream_receiver import RecordingController, receiver_with_udp

BURST = 100  # well within the socket's receive buffer: none dropped
LINE = b"1.5 0 2 0 0.1 0\n"  # six numbers: numbered on arrival, never out of order


def test_udp_datagrams_taken_per_burst(benchmark) -> None:
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, udp):
        def burst() -> None:
            expected = receiver.counters.received + BURST
            deadline = time.monotonic() + HANG_S  # bounds a hang only
            for _ in range(BURST):
                udp.send(LINE)
            while receiver.counters.received < expected:  # a spin: a sleep's granularity would be the figure
                assert time.monotonic() < deadline, f"{receiver.counters.received} of {expected} datagrams taken"
                time.sleep(0)

        benchmark.pedantic(burst, rounds=30 if benchmark.enabled else 1, warmup_rounds=1 if benchmark.enabled else 0)
        wait_for(lambda: controller.targets, "a target handed on")
        counters = receiver.counters
        assert counters.malformed == counters.out_of_order == 0
        assert counters.received == BURST * (31 if benchmark.enabled else 1)
