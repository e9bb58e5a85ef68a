"""The stream's receiver on its own, in front of a recording controller: samples that come
faster than the loop's period reach the controller once a period at most, on average,
and the newest wins."""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from types import SimpleNamespace

import pytest
import zmq
from hypothesis import given
from hypothesis import strategies as st

from hexactl.adapters.api import stream_receiver
from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.messages import StreamOpenRequest
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.stream_receiver import StreamReceiver
from hexactl.adapters.api.stream_wire import MalformedSample, decode, encode
from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.control.stream import StreamPhase, StreamProgress
from hexactl.control.stream_commands import TargetResult
from tests.api.support import FakeController, FakeStreamInput
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
        self.poses: list[tuple[float, ...]] = []

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        self.targets.append((time.monotonic_ns(), sequence))
        self.poses.append(tuple(pose))
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


class FailingController(RecordingController):
    """Fails to take the target with ``failing`` as its sequence; records the others."""

    def __init__(self, failing: int) -> None:
        super().__init__()
        self.failing = failing

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        if sequence == self.failing:
            raise RuntimeError("a controller that fails")
        return super().stream_target(pose, sequence, sent_s, received_ns, before)


@contextmanager
def receiver_with_udp(controller: RecordingController) -> Iterator[tuple[StreamReceiver, zmq.Socket, socket.socket]]:
    """A started receiver with a UDP port, a PUSH socket and a UDP socket connected to it."""
    progress = StreamProgress(1, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
    with zmq.Context() as context:
        receiver = StreamReceiver(context, "tcp://127.0.0.1:*", ("127.0.0.1", 0), controller.stream_target, PERIOD_S,
                                  lambda: progress)
        receiver.start()
        push = context.socket(zmq.PUSH)
        push.linger = 0
        push.connect(receiver.endpoint)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        host, port = receiver.endpoints["udp"].rsplit(":", 1)
        udp.connect((host, int(port)))
        try:
            yield receiver, push, udp
        finally:
            udp.close()
            push.close()
            receiver.close()


def sent(send, message, until, what: str) -> None:
    """``send(message)``, then wait until ``until()`` says the receiver has dealt with it:
    each message is taken alone, in order, however slowly the receiver's thread runs (no
    coalescing, no race between the ZeroMQ and the UDP socket)."""
    send(message)
    wait_for(until, what)


def sequences(controller: RecordingController) -> list[int]:
    return [sequence for _, sequence in controller.targets]


def test_a_sender_time_too_large_for_any_clock_is_malformed_and_the_input_goes_on() -> None:
    """Found from outside: sent_s 1e300 (finite) overflowed the age in nanoseconds, and the
    exception ended the receiver's thread for good while status looked healthy."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, udp):
        sent(push.send, encode(1, 1e300, [0.0] * 6), lambda: receiver.counters.malformed == 1,
             "the binary sample refused")
        sent(udp.send, b"2 1e300 0 0 1 0 0 0\n", lambda: receiver.counters.malformed == 2, "the text sample refused")
        sent(udp.send, encode(3, time.monotonic(), [1.0, 0, 0, 0, 0, 0]), lambda: sequences(controller) == [3],
             "the good sample to go on")
        assert receiver.running and "sent_s is a time in s within" in receiver.counters.last_problem


@pytest.mark.parametrize(("sent_s", "pose"), [
    (86737.31, (100.0, 0, 5.0, 0.1, 0, 0)), (1.7e9, (100.0, 0, 5.0, 0.1, 0, 0)), (0.01, (0.0,) * 6),
    (86737.31, (0.0,) * 6), (0.0, (-2.5, 1e-3, 0, 0, 0, 180.0)), (12.5, (-2.5, 1e-3, 0, 0, 0, 180.0)),
])  # not all zeros: that reads the same in either byte order
def test_a_big_endian_binary_sample_is_refused_saying_so(sent_s, pose) -> None:
    """Found from outside: half of a big-endian sender's samples were taken, their poses
    subnormal (about 1e-317), the zero posture the platform then went to."""
    import struct

    with pytest.raises(MalformedSample, match="the numbers are big-endian"):
        decode(struct.pack(">4sId6d", b"HXS1", 7, sent_s, *pose))


@pytest.mark.parametrize(("sent_s", "pose"), [
    (12.5, (1e-310, 0, 0, 0, 0, 0)), (0.0, (5e-324, 0, 0, 0, 0, 0)), (1e-310, (0,) * 6),  # refused by a first rule
    (3.0, (100 * math.sin(math.pi), 0, 0, 0, 0, 0)),  # a sine's residue at its zero, 1.2e-14
])
def test_a_little_endian_sample_with_a_tiny_value_is_taken(sent_s, pose) -> None:
    assert decode(encode(7, sent_s, pose)).pose == pytest.approx(pose, abs=0)


plausible = st.one_of(st.just(0.0), st.floats(1e-9, 1e6), st.floats(-1e6, -1e-9))


@given(sent_s=st.one_of(st.just(0.0), st.floats(1e-9, 1e10)), pose=st.tuples(*[plausible] * 6))
def test_a_little_endian_sample_of_values_a_sender_means_is_never_refused(sent_s, pose) -> None:
    """Found from outside: a first rule refused 11,659 of 200,000 such samples as big-endian."""
    assert decode(encode(7, sent_s, pose)).pose == pose


def test_a_big_endian_sender_of_a_moving_pose_is_refused_sample_after_sample() -> None:
    """Found from outside: a rule that looked at subnormals only took 640 of 5000 samples
    of a big-endian sine sender, poses of about 1e-236."""
    import struct

    taken = 0
    for n in range(5000):
        t = 86737.31 + n * 0.002
        pose = (100 * math.sin(math.pi * t), 0, 0, 5 * math.sin(math.pi * t), 0, 0)
        try:
            decode(struct.pack(">4sId6d", b"HXS1", n, t, *pose))
        except MalformedSample:
            continue
        taken += 1
    assert taken == 0


def test_an_error_handing_a_target_on_is_counted_and_the_next_target_goes_on() -> None:
    controller = FailingController(failing=1)
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: receiver.counters.failed == 1,
             "the failing hand-over counted")
        sent(push.send, encode(2, time.monotonic(), [0.1, 0, 0, 0, 0, 0]), lambda: sequences(controller) == [2],
             "the next sample to go on")
        view = receiver.view()
        assert view["running"] and view["failed"] == 1 and view["forwarded"] == 1
        assert "target 1 could not be handed to the loop: RuntimeError" in view["last_problem"]


def test_a_message_of_several_frames_is_not_a_sample() -> None:
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send_multipart, [encode(1, time.monotonic(), [0.0] * 6), b"extra"],
             lambda: receiver.counters.malformed == 1, "the message refused")
        sent(push.send, encode(2, time.monotonic(), [0.1, 0, 0, 0, 0, 0]), lambda: controller.targets,
             "the one-frame sample to go on")
        assert sequences(controller) == [2] and receiver.counters.received == 2
        assert "one frame, this one has 2" in receiver.counters.last_problem


def test_a_message_far_larger_than_any_sample_is_not_read_and_its_sender_is_cut_off() -> None:
    """Found from outside: the stream socket read messages of any size, each whole into
    memory, for the receiver to refuse; three of 600 MB took the API's process to 2.4 GB
    and kept its E-stop path silent for 2.8 s, and larger ones would exhaust the memory.
    A message beyond MAX_MESSAGE_BYTES now closes its sender's connection unread; one up to
    it is still read and refused with its reason."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _), zmq.Context() as context:
        sent(push.send, b"x" * stream_receiver.MAX_MESSAGE_BYTES, lambda: receiver.counters.malformed == 1,
             "a message up to the bound read and refused")
        flooding = context.socket(zmq.PUSH)
        flooding.linger = 0
        cut_off = flooding.get_monitor_socket(zmq.EVENT_DISCONNECTED)
        flooding.connect(receiver.endpoint)
        try:
            flooding.send(bytes(stream_receiver.MAX_MESSAGE_BYTES + 1))
            wait_for(lambda: receiver.counters.malformed > 1 or cut_off.poll(0),
                     "the sender cut off, or its message read")
            assert receiver.counters.malformed == 1 and receiver.counters.received == 1
        finally:
            flooding.disable_monitor()
            cut_off.close()
            flooding.close()
        sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: sequences(controller) == [1],
             "another sender's sample to go on")


def test_a_six_number_line_is_the_newest_and_does_not_let_an_old_sample_back_in() -> None:
    """Found from outside: a 6-number line was numbered by arrival (1, 2, …), which let a
    binary sample older than the last one taken in again after it."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(100, time.monotonic(), [0.0] * 6), lambda: sequences(controller) == [100], "sample 100")
        sent(push.send, encode(50, time.monotonic(), [5.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.out_of_order == 1,
             "sample 50 dropped")
        sent(push.send, b"1 0 0 0 0 0\n", lambda: len(controller.targets) == 2, "the line to go on")
        sent(push.send, encode(50, time.monotonic(), [9.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.out_of_order == 2,
             "the second sample 50 dropped")
        assert sequences(controller) == [100, 101] and receiver.counters.out_of_order == 2


@pytest.mark.parametrize("line", [b"1_0 0 0 0 0 0", b"inf 0 0 0 0 0", b"0x10 0 0 0 0 0", b"nan 0 0 0 0 0"])
def test_a_text_line_takes_decimal_numbers_only(line: bytes) -> None:
    with pytest.raises(MalformedSample, match="text line of decimal numbers"):
        decode(line)


def test_stream_open_is_refused_once_the_input_has_stopped(tmp_path) -> None:
    stopped = FakeStreamInput()
    stopped.running = False
    handler = CommandHandler(FakeController(load_geometry(default_config_path())), DataDirectories([tmp_path]),
                             stream_input=stopped)
    with pytest.raises(ApiError) as refused:
        handler(StreamOpenRequest(v=1, id=1, cmd="stream_open", source="simulator", timeout_ms=100))
    assert refused.value.code == ErrorCode.NO_STREAM_INPUT and "restart the service" in refused.value.message


def test_the_rate_of_a_sender_faster_than_the_samples_kept_is_not_capped_at_their_number(monkeypatch) -> None:
    """Found from outside: a 5 kHz sender showed rate_hz 2000, the number of arrival times
    kept (KEPT_LATENCIES). The receiver is driven here on a clock of the test's own."""
    now_ns = [10**9]
    monkeypatch.setattr(stream_receiver, "time", SimpleNamespace(monotonic_ns=lambda: now_ns[0]))
    progress = StreamProgress(1, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
    with zmq.Context() as context:
        receiver = StreamReceiver(context, "tcp://127.0.0.1:*", None, RecordingController().stream_target, PERIOD_S,
                                  lambda: progress)
        try:
            receiver._watch_loop()
            for sequence in range(1, 5001):  # 5 kHz for a second
                now_ns[0] += 200_000
                receiver._taken_or_counted([encode(sequence, now_ns[0] / 1e9, [0.0] * 6)], stream_receiver.ZEROMQ)
            assert receiver.view()["rate_hz"] == 5000
            now_ns[0] += 2 * 10**9  # quiet for two seconds
            assert receiver.view()["rate_hz"] == 0
        finally:
            receiver.close()


def test_a_sender_that_restarts_its_count_is_told_why_its_samples_are_dropped() -> None:
    """Found from outside: a simulator restarted mid-stream numbers its samples from 0 again;
    every one was dropped as out of order, the stream ended in its timeout, and last_problem
    said nothing: the operator saw a timeout while the simulator was sending."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(5000, time.monotonic(), [0.0] * 6), lambda: sequences(controller) == [5000], "sample 5000")
        # waited for by its count: the receiver says why before it counts
        sent(push.send, encode(1, time.monotonic(), [1.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.out_of_order == 1,
             "sample 1 dropped")
        assert receiver.counters.out_of_order == 1
        problem = receiver.counters.last_problem
        assert "sample 1 is not above the last one taken (5000)" in problem and "a new stream" in problem


def test_a_flood_does_not_hold_up_the_targets_while_it_is_read(monkeypatch) -> None:
    """Found from outside: under a UDP flood of a few thousand samples a second on a busy host
    the thread read 1024 per wake, 100-250 ms, before it forwarded one: 6 targets a second
    reached the loop and the stream ended in its timeout. Here the receiver is not started
    and reads by hand, on a clock on which each look costs 100 µs, 500 samples waiting in
    its port: targets go on, a period apart, while they are read."""
    now_ns = [time.monotonic_ns()]

    def slow_clock() -> int:
        now_ns[0] += 100_000
        return now_ns[0]

    monkeypatch.setattr(stream_receiver, "time", SimpleNamespace(monotonic_ns=slow_clock))
    controller = RecordingController()
    progress = StreamProgress(1, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
    with zmq.Context() as context:
        receiver = StreamReceiver(context, "tcp://127.0.0.1:*", ("127.0.0.1", 0), controller.stream_target, PERIOD_S,
                                  lambda: progress)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            host, port = receiver.endpoints["udp"].rsplit(":", 1)
            for sequence in range(1, 501):  # on loopback each is in the port once sent
                udp.sendto(encode(sequence, sequence * 1e-4, [0.0] * 6), (host, int(port)))
            receiver._watch_loop()
            receiver._read()
            assert receiver.counters.received == 500
            assert len(controller.targets) >= 5 and sequences(controller) == sorted(set(sequences(controller)))
        finally:
            udp.close()
            receiver.close()


def udp_socket(receiver: StreamReceiver) -> socket.socket:
    """Another sender: a UDP socket of its own (another port) connected to the receiver."""
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    host, port = receiver.endpoints["udp"].rsplit(":", 1)
    other.connect((host, int(port)))
    return other


def test_a_second_udp_sender_is_not_followed() -> None:
    """Found from outside: two programs sending unnumbered lines to the stream's port (a
    second simulator started by mistake) swung the platform between their poses, and
    nothing said why. Once the second has sent SENDER_DATAGRAMS lines too, only the first
    is followed; the other's lines are counted and dropped, and last_problem names both."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, first), udp_socket(receiver) as second:
        taken = lambda count: lambda: len(controller.targets) == count  # noqa: E731
        for number in range(stream_receiver.SENDER_DATAGRAMS):
            sent(first.send, f"{number} 0 0 0 0 0\n".encode(), taken(2 * number + 1), "the first sender's line")
            if number < stream_receiver.SENDER_DATAGRAMS - 1:
                sent(second.send, f"{50 + number} 0 0 0 0 0\n".encode(), taken(2 * number + 2),
                     "the second sender's line, before it counts as a sender")
        followed = len(controller.targets)
        sent(second.send, b"60 0 0 0 0 0\n", lambda: receiver.counters.other_sender == 1, "the second sender dropped")
        sent(first.send, b"7 0 0 0 0 0\n", taken(followed + 1), "the first sender followed on")
        sent(second.send, b"61 0 0 0 0 0\n", lambda: receiver.counters.other_sender == 2, "the second sender dropped")
        assert len(controller.targets) == followed + 1
        problem = receiver.counters.last_problem
        own, other = (f"127.0.0.1:{s.getsockname()[1]}" for s in (first, second))
        assert problem.startswith(f"samples from UDP {other} dropped: UDP {own} is this stream's sender"), problem
        assert receiver.view()["other_sender"] == 2


def test_once_the_stream_has_its_sender_a_stray_datagram_is_dropped_from_the_first() -> None:
    """Found from outside: one datagram from another socket, numbered 99999, was taken (a
    second sender's first datagrams were, before it counted as one): the platform swung
    40 mm towards its pose, and every later sample of the stream's own sender was dropped
    as out of order until the stream timed out. Once the sender is found, another
    address's datagrams are dropped from the first, named."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, first), udp_socket(receiver) as stray:
        taken = lambda count: lambda: len(controller.targets) == count  # noqa: E731
        found = stream_receiver.SENDER_DATAGRAMS
        for number in range(1, found + 1):
            sent(first.send, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]), taken(number), "the first's")
        sent(stray.send, encode(99999, 0.01, [-20.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.other_sender == 1,
             "the stray dropped")
        for number in range(found + 1, found + 4):
            sent(first.send, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]), taken(number), "the first's")
        assert sequences(controller) == list(range(1, found + 4)) and receiver.counters.out_of_order == 0
        assert all(pose[0] == 20.0 for pose in controller.poses)
        stray_address = f"127.0.0.1:{stray.getsockname()[1]}"
        assert receiver.counters.last_problem.startswith(f"samples from UDP {stray_address} dropped: "), \
            receiver.counters.last_problem


def test_a_stray_datagram_taken_before_the_sender_was_found_does_not_rank_its_samples() -> None:
    """Before the sender is found (its first datagrams) a stray is taken like any; once the
    sender is found, the stray's number no longer ranks the sender's samples."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, first), udp_socket(receiver) as stray:
        sent(stray.send, encode(99999, 0.01, [-20.0, 0, 0, 0, 0, 0]), lambda: len(controller.targets) == 1,
             "the stray, taken: no sender yet")
        found = stream_receiver.SENDER_DATAGRAMS
        for number in range(1, found):  # below the stray's number: out of order
            sent(first.send, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]),
                 lambda n=number: receiver.counters.out_of_order == n, "the first's, below the stray's")
        for number in range(found, found + 3):  # the sender found: followed on
            sent(first.send, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]),
                 lambda n=number: sequences(controller)[-1:] == [n], "the first's, followed")
        sent(stray.send, encode(100000, 0.02, [-20.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.other_sender == 1,
             "the stray dropped")
        assert sequences(controller) == [99999, *range(found, found + 3)]


def test_an_oversized_datagram_is_refused_with_its_own_size() -> None:
    """Found from outside: a datagram of 3000 bytes was said to be of 2048, the size read."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, udp):
        sent(udp.send, b"1" * 3000, lambda: receiver.counters.malformed == 1, "the datagram refused")
        assert receiver.counters.last_problem.endswith("(3000 bytes)"), receiver.counters.last_problem


def test_a_sender_with_a_new_port_for_every_datagram_is_followed_whole() -> None:
    """Software that opens a socket per datagram sends each from another port: never two
    senders taking turns, so nothing of it is dropped."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, _udp):
        for number in range(1, 4 * stream_receiver.SENDER_DATAGRAMS):
            with udp_socket(receiver) as once:
                sent(once.send, f"{number} 0 0 0 0 0\n".encode(), lambda n=number: len(controller.targets) == n,
                     f"line {number}")
        assert receiver.counters.other_sender == 0 and len(controller.targets) == 4 * stream_receiver.SENDER_DATAGRAMS - 1


class BehindController(RecordingController):
    """Says each target was dropped on the way to the loop, the loop being behind."""

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        super().stream_target(pose, sequence, sent_s, received_ns, before)
        return TargetResult(True, clamped=True, dropped=True)


def test_a_target_dropped_on_the_way_to_the_loop_is_not_counted_forwarded() -> None:
    """The link drops a stream's target while commands wait unread for the loop; the
    receiver counted it forwarded (and clamped), and ``hexactl cue`` printed that count."""
    controller = BehindController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: receiver.counters.loop_behind == 1,
             "the target dropped on the way counted")
        view = receiver.view()
        assert view["forwarded"] == 0 and view["clamped"] == 0 and view["loop_behind"] == 1


def test_after_a_stream_closes_the_counts_still_name_it_until_the_next_opens() -> None:
    """Found from outside: once the stream closed, ``stream`` became null while the counts
    beside it were still that stream's: a reader could not tell whose they were."""
    controller = RecordingController()
    progress = [StreamProgress(7, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)]
    with zmq.Context() as context:
        receiver = StreamReceiver(context, "tcp://127.0.0.1:*", None, controller.stream_target, PERIOD_S,
                                  lambda: progress[0])
        receiver.start()
        push = context.socket(zmq.PUSH)
        push.linger = 0
        push.connect(receiver.endpoint)
        try:
            sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: sequences(controller) == [1], "sample 1")
            assert receiver.view()["stream"] == 7
            progress[0] = None  # closed
            sent(push.send, encode(2, time.monotonic(), [0.0] * 6), lambda: receiver.counters.no_stream == 1,
                 "sample 2 taken with no stream open")
            view = receiver.view()
            assert (view["stream"], view["forwarded"], view["no_stream"]) == (7, 1, 1), view
            # Found from outside: a PUSH or UDP sender hears nothing back; its samples after the
            # stream ended were only counted, and last_problem kept an old word or none.
            assert view["last_problem"] == ("samples arrive with no stream open (the last one ended: telemetry's "
                                            "last_stream says why): they move nothing; stream_open to stream again")
            # Found from outside: what went wrong while the stream was open (the reason it timed
            # out) was replaced by this within a cycle: it stays, said after it.
            progress[0] = StreamProgress(8, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
            wait_for(lambda: receiver.view()["stream"] == 8, "the next stream's counts")
            assert receiver.view()["forwarded"] == 0
            sent(push.send, b"1 2 3", lambda: receiver.counters.malformed == 1,
                 "a malformed sample in stream 8")
            problem = receiver.counters.last_problem
            progress[0] = None  # ended
            sent(push.send, encode(2, time.monotonic(), [0.0] * 6), lambda: receiver.counters.no_stream == 1,
                 "a sample after stream 8 ended")
            assert receiver.view()["last_problem"] == (
                "samples arrive with no stream open (the last one ended: telemetry's last_stream says why): they move "
                f"nothing; stream_open to stream again; the last problem while it was open: {problem}")
        finally:
            push.close()
            receiver.close()


@pytest.mark.parametrize(("clock", "said"), [(lambda t: t * 1000.0, True), (lambda t: 0.0, True),
                                             (lambda t: t, False)], ids=["milliseconds", "constant", "seconds"])
def test_a_sent_s_that_is_not_seconds_is_said(clock, said: bool) -> None:
    """Found from outside: sent_s in milliseconds, or left 0, made the platform follow the
    stream stop-and-go at a fraction of its speed, and nothing said why."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        for sequence in range(1, stream_receiver.SENT_CLOCK_SAMPLES + 4):
            time.sleep(0.005)  # paced: arrivals apart by more than a burst's
            sent(push.send, encode(sequence, clock(time.monotonic()), [0.0] * 6),
                 lambda s=sequence: receiver.counters.received == s, f"sample {sequence}")
        problem = receiver.counters.last_problem
        assert ("sent_s is the sender's clock in seconds (not milliseconds, not a constant)" in problem) == said, problem
        assert receiver.counters.malformed == receiver.counters.out_of_order == 0  # nothing dropped for it


def test_a_line_without_a_sequence_after_the_largest_is_dropped_saying_why() -> None:
    """Found from outside: it was numbered 2³², beyond any sample's, and every sample after
    it was dropped as out of order."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(2**32 - 1, time.monotonic(), [0.0] * 6), lambda: receiver.counters.received == 1,
             "the largest sequence")
        # waited for by its count: the receiver says why before it counts
        sent(push.send, b"0 0 0 0 0 0", lambda: receiver.counters.out_of_order == 1, "the line dropped")
        assert receiver.counters.out_of_order == 1
        assert "has reached 4294967295, the largest" in receiver.counters.last_problem
        assert sequences(controller) == [2**32 - 1]  # the line went nowhere


class JoiningController(RecordingController):
    """Says each target is a sample far from the platform, joined as a step."""

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        super().stream_target(pose, sequence, sent_s, received_ns, before)
        return TargetResult(True, joining=(600.0, 0.0))


def test_a_sample_far_from_the_platform_is_said_to_be_joined_as_a_step() -> None:
    """Found from outside: a stream whose first samples were 600 mm from the platform was
    taken without a word (then lunged at; now joined at rest): the sender is told why the
    platform does not follow it at its speed, and what to do."""
    controller = JoiningController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: receiver.counters.last_problem,
             "the target handed over and said")  # the problem is set after the count: wait for what is judged
        assert receiver.counters.last_problem == (
            "sample 1 is 600.0 mm and 0.00° from the platform: beyond 20 mm or 2° the stream is joined as a step, at "
            "rest, not followed at its speed; move the platform to the stream's first pose before stream_open "
            "(hexactl cue does)")


class HoldingController(RecordingController):
    """Says each target was out of reach and held at x 610 mm."""

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None) -> TargetResult:
        super().stream_target(pose, sequence, sent_s, received_ns, before)
        return TargetResult(True, clamped=True, goal=(610.0, 0.0, 0.0, 0.0, 0.0, -179.5))


def test_a_sample_out_of_reach_says_where_the_platform_is_held_and_how_far_short() -> None:
    """Found from outside: a stream held on the workspace's boundary (x 610 mm, samples at
    900) showed only a growing count, "255 clamped", beside a status that looked normal."""
    controller = HoldingController()
    with receiver_with_udp(controller) as (receiver, push, _):
        sent(push.send, encode(1, time.monotonic(), [900.0, 0, 0, 0, 0, 179.5]), lambda: receiver.counters.last_problem,
             "the target held short and said")  # the problem is set after the count: wait for what is judged
        assert receiver.counters.last_problem == (
            "sample 1 is out of reach (a hardware or soft limit): the platform is held at (610.0, 0.0, 0.0, 0.0, 0.0, "
            "-179.5) mm and deg, the nearest reachable pose on the way, 290.0 mm and 1.00° short of it; hexactl check "
            "with the sample's pose names the limit")


def test_a_zeromq_sender_whose_connection_closes_during_a_stream_is_said(receiving) -> None:
    """Found from outside: a message over the size limit had ZeroMQ close its sender's
    connection, unread; the stream then timed out and nothing said why."""
    receiver, controller, push = receiving
    sent(push.send, encode(1, time.monotonic(), [0.0] * 6), lambda: sequences(controller) == [1], "sample 1")
    push.send(b"0 0 0 0 0 0" + b" " * stream_receiver.MAX_MESSAGE_BYTES)
    wait_for(lambda: "connection to stream 1 closed" in receiver.counters.last_problem, "the closed connection said",
             seen=lambda: receiver.counters.last_problem)
    assert receiver.counters.last_problem.startswith(
        f"a ZeroMQ sender's connection to stream 1 closed: the sender ended, or sent a message over "
        f"{stream_receiver.MAX_MESSAGE_BYTES} bytes")


def test_malformed_datagrams_do_not_make_their_address_the_streams_sender() -> None:
    """Found from outside: three datagrams "hello" from a stray program, sent before the
    stream's own sender began, made that address the sender: every sample of the real one
    was then dropped, and the stream timed out."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, _, first), udp_socket(receiver) as stray:
        for count in range(1, stream_receiver.SENDER_DATAGRAMS + 1):
            sent(stray.send, b"hello", lambda n=count: receiver.counters.malformed == n, "a malformed datagram")
        for number in range(1, stream_receiver.SENDER_DATAGRAMS + 3):
            sent(first.send, encode(number, number * 0.002, [1.0, 0, 0, 0, 0, 0]),
                 lambda n=number: sequences(controller)[-1:] == [n], "the sender's sample followed")
        assert receiver.counters.other_sender == 0
        sent(stray.send, encode(99999, 0.1, [-20.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.other_sender == 1,
             "the stray's well-formed sample dropped: the sender is the first")


@pytest.mark.parametrize("transport", ["udp", "zeromq"])
def test_a_sample_from_the_other_transport_is_dropped_once_the_stream_has_its_sender(transport) -> None:
    """Found from outside: once a UDP stream had its sender, one ZeroMQ message numbered
    99999 was taken: the platform headed for its pose, and every later sample of the UDP
    sender was dropped as out of order until the stream timed out. ZeroMQ is a sender of
    its own, told apart from each UDP address, both ways round."""
    controller = RecordingController()
    with receiver_with_udp(controller) as (receiver, push, udp):
        udp_name = f"UDP 127.0.0.1:{udp.getsockname()[1]}"
        (own, own_name), (other, other_name) = (((udp.send, udp_name), (push.send, "ZeroMQ")) if transport == "udp"
                                                else ((push.send, "ZeroMQ"), (udp.send, udp_name)))
        found = stream_receiver.SENDER_DATAGRAMS
        for number in range(1, found + 1):
            sent(own, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]),
                 lambda n=number: sequences(controller)[-1:] == [n], "the sender's sample")
        sent(other, encode(99999, 0.01, [-20.0, 0, 0, 0, 0, 0]), lambda: receiver.counters.other_sender == 1,
             "the other transport's sample dropped")
        for number in range(found + 1, found + 4):
            sent(own, encode(number, number * 0.002, [20.0, 0, 0, 0, 0, 0]),
                 lambda n=number: sequences(controller)[-1:] == [n], "the sender's sample, followed on")
        assert sequences(controller) == list(range(1, found + 4)) and receiver.counters.out_of_order == 0
        assert all(pose[0] == 20.0 for pose in controller.poses)
        assert receiver.counters.last_problem.startswith(f"samples from {other_name} dropped: {own_name} is this "
                                                         "stream's sender"), receiver.counters.last_problem
