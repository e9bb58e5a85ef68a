"""The stream's receiver on its own, in front of a recording controller: samples that come
faster than the loop's period reach the controller once a period at most, on average,
and the newest wins."""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence

import pytest
import zmq

from hexactl.adapters.api.stream_receiver import StreamReceiver
from hexactl.adapters.api.stream_wire import encode
from hexactl.control.stream import StreamPhase, StreamProgress
from hexactl.control.stream_commands import TargetResult
from tests.reliability.support import wait_for

PERIOD_S = 0.01
"""The receiver's period."""
SAMPLES = 2000
BURST = 10
"""Samples sent back to back, then a millisecond's pause: a burst arrives far within a period
however busy the machine is, so all but one of each are coalesced."""


class RecordingController:
    """``stream_target`` that records when each target came and which sample it was."""

    def __init__(self) -> None:
        self.targets: list[tuple[int, int]] = []  # (monotonic ns, sequence)

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        self.targets.append((time.monotonic_ns(), sequence))
        return TargetResult(True)


@pytest.fixture
def receiving() -> Iterator[tuple[StreamReceiver, RecordingController, zmq.Socket]]:
    controller = RecordingController()
    progress = StreamProgress(1, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
    with zmq.Context() as context:
        receiver = StreamReceiver(context, "tcp://127.0.0.1:*", None, controller.stream_target, PERIOD_S,
                                  lambda: progress)
        receiver.start()
        push = context.socket(zmq.PUSH)
        push.linger = 0
        push.connect(receiver.endpoint)
        try:
            yield receiver, controller, push
        finally:
            push.close()
            receiver.close()


def send_samples(push: zmq.Socket, first: int, count: int) -> None:
    """``count`` samples numbered from ``first``, in bursts of :data:`BURST`."""
    for sequence in range(first, first + count):
        push.send(encode(sequence, time.monotonic(), [0.01 * sequence, 0.0, 0.0, 0.0, 0.0, 0.0]))
        if sequence % BURST == 0:
            time.sleep(0.001)


def assert_once_a_period_at_most(targets: list[tuple[int, int]]) -> None:
    """However late the thread wakes, each hand-over is due a period after the one before was."""
    assert (len(targets) - 1) * PERIOD_S * 1e9 <= targets[-1][0] - targets[0][0], len(targets)


def test_samples_faster_than_the_period_go_on_once_a_period_at_most_the_newest_winning(receiving) -> None:
    receiver, controller, push = receiving
    send_samples(push, 1, SAMPLES)
    wait_for(lambda: controller.targets and controller.targets[-1][1] == SAMPLES, "the newest sample to go on")
    assert_once_a_period_at_most(controller.targets)
    sequences = [sequence for _, sequence in controller.targets]
    assert sequences == sorted(set(sequences))  # each once, in order
    counters = receiver.counters
    assert counters.received == SAMPLES and counters.forwarded == len(sequences)
    assert counters.coalesced == SAMPLES - len(sequences) > 0


def test_after_a_quiet_spell_the_periods_missed_are_not_caught_up(receiving) -> None:
    _, controller, push = receiving
    send_samples(push, 1, 1)
    wait_for(lambda: len(controller.targets) == 1, "the first sample to go on")
    time.sleep(20 * PERIOD_S)
    more = 1000
    send_samples(push, 2, more)
    wait_for(lambda: controller.targets[-1][1] == 1 + more, "the newest sample to go on")
    assert_once_a_period_at_most(controller.targets[1:])
