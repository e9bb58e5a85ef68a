"""The pose stream's input: a ZeroMQ PULL socket and, optionally, a UDP port, read by a thread of their own.

Samples (:mod:`hexactl.adapters.api.stream_wire`) arrive at whatever rate the sender
keeps; the loop takes one target a cycle. So the receiver reads everything that
arrived, drops what is malformed, out of order or duplicated (each counted), keeps the
newest sample and hands it to the controller (which makes it reachable and queues it
for the loop: :meth:`~hexactl.control.controller.Controller.stream_target`) once a loop
period at most, on average: each hand-over is due a period after the one before was due,
so the millisecond by which a wake-up can be late does not lower the rate. What it counts
and how late the targets reach the loop are in telemetry's ``stream_input``
(:meth:`StreamReceiver.view`).

Samples that arrive while no stream is open are counted and dropped: a stream is opened
by the ``stream_open`` command, never by its data.

Nothing a sender does stops the thread: a message that cannot be taken, for whatever
reason, is counted as malformed, and an error handing a target to the controller is
logged and counted; the thread goes on with the next. Should it end all the same,
``running`` says so in telemetry and ``stream_open`` is refused.
"""

from __future__ import annotations

import collections
import logging
import socket
import time
from collections.abc import Callable, Sequence
from math import degrees
from typing import Any

import zmq
from zmq.utils.monitor import recv_monitor_message

from hexactl.adapters.api.security import CurveServer
from hexactl.adapters.api.socket_thread import SocketThread
from hexactl.adapters.api.stream_wire import LAST_SEQUENCE, MAX_TEXT_BYTES, MalformedSample, Sample, decode
from hexactl.control.stream import StreamProgress
from hexactl.control.stream_commands import JOIN_DISTANCE, TargetResult

POLL_MS = 100
"""How often the idle thread wakes to check for shutdown."""

MAX_PER_WAKE = 1024
"""Messages read per wake at most: a flood cannot keep the thread from looking at the
loop's stream or from stopping (targets go on while it reads: :meth:`StreamReceiver._read`)."""

KEPT_LATENCIES = 2000
"""Latencies kept for the percentiles (4 s at 500 Hz)."""

UDP_BUFFER_BYTES = 1 << 20

MAX_MESSAGE_BYTES = 8 * MAX_TEXT_BYTES
"""``zmq.MAXMSGSIZE`` of the stream socket: ZeroMQ closes the connection of a sender whose
message is larger, unread (read whole into memory first, a message of gigabytes exhausted
the API's process); so the receive queue holds at most RCVHWM times this. Up to it a
message is read and refused with its reason."""

ZEROMQ = "ZeroMQ"
"""The sender of every ZeroMQ message: a PUSH socket names no sender, so all of them are one,
told apart from each UDP address."""

SENDER_DATAGRAMS = 3
"""Samples of the last :data:`SENDER_WINDOW` a sender (a UDP address, or ZeroMQ) sends to a
stream to become its sender."""

SENDER_WINDOW = 8
"""The samples, the stream's last, in which its sender is found. A UDP sender with a socket of
its own sends all of them; one that opens a socket per datagram sends each from a new port,
the kernel's pick among thousands, and none of those comes back three times in eight."""

LOG_INTERVAL_S = 1.0
"""A new problem with the input is logged at most this often (all are counted)."""

SENT_CLOCK_BAND = (0.05, 20.0)
"""How much ``sent_s`` may advance per second of arrival between two samples and pass for
the sender's clock in seconds (jitter and bursts stay inside; a clock in milliseconds
advances 1000, a constant 0)."""

SENT_CLOCK_SAMPLES = 10
"""Samples in a row whose ``sent_s`` leaves :data:`SENT_CLOCK_BAND` before it is said."""

_ARRIVAL_PACE_NS = 2_000_000  # two samples closer than this arrived in a burst: no pace to compare with

log = logging.getLogger("hexactl.stream")

Target = Callable[[Sequence[float], int, float, int, tuple[Sequence[float], float] | None], TargetResult]
"""The controller's ``stream_target(pose, sequence, sent_s, received_ns, before)``."""


class StreamCounters:
    """What the receiver counted since the stream it last saw opened."""

    def __init__(self) -> None:
        self.received = 0  # messages read, well formed or not
        self.malformed = 0
        self.out_of_order = 0  # a sequence not above the last one taken: reordered or duplicated
        self.other_sender = 0  # from another sender than the stream's (a UDP address, or ZeroMQ): dropped
        self.no_stream = 0  # well formed, but no stream open
        self.coalesced = 0  # superseded by a newer sample before the loop's next turn (not lost: newer wins)
        self.forwarded = 0  # reached the loop's pipe (or inbox)
        self.loop_behind = 0  # dropped on the way: the loop was behind reading its commands (the next replaces it)
        self.clamped = 0  # out of reach, replaced by the nearest reachable pose on the way
        self.failed = 0  # could not be handed to the controller (an error, logged)
        self.last_problem = ""


class StreamReceiver(SocketThread):
    """The stream socket bound to ``endpoint`` (``tcp://HOST:*``: a free port; CURVE
    with ``curve``) and, with ``udp`` (host, port), a UDP socket; samples go to
    ``target`` once every ``period_s`` at most, on average; ``progress()`` is the loop's stream.

    :raises zmq.ZMQError: the endpoint is malformed or in use
    :raises OSError: the UDP address cannot be bound (nothing is left open)
    """

    def __init__(self, context: zmq.Context, endpoint: str, udp: tuple[str, int] | None, target: Target,
                 period_s: float, progress: Callable[[], StreamProgress | None],
                 curve: CurveServer | None = None) -> None:
        super().__init__(context, zmq.PULL, endpoint, name="hexactl-stream", curve=curve,
                         options={zmq.RCVHWM: 10_000, zmq.MAXMSGSIZE: MAX_MESSAGE_BYTES})
        # A sender's connection closed is said: ZeroMQ closes it, unread, for a message over
        # MAX_MESSAGE_BYTES, and the stream then timed out with nothing said (found from outside).
        self._monitor = self._socket.get_monitor_socket(zmq.EVENT_DISCONNECTED)
        self._udp: socket.socket | None = None
        if udp is not None:
            try:
                self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self._udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_BUFFER_BYTES)
                self._udp.bind(udp)
                self._udp.setblocking(False)
            except OSError:
                if self._udp is not None:
                    self._udp.close()
                self._close_monitor()
                self._socket.close()
                raise
        self._target = target
        self._period_ns = round(period_s * 1e9)
        self._progress = progress
        self.counters = StreamCounters()
        self._stream: int | None = None  # the loop's stream open now
        self._counted: int | None = None  # the stream the counters are for: the open one, or the last
        self._last_sequence: int | None = None
        self._recent_senders: collections.deque[Any] = collections.deque(maxlen=SENDER_WINDOW)  # until one is found
        self._sender: Any = None  # the stream's sender, once found: the only one followed from then on
        self._last_from: Any = None  # who sent the newest sample taken
        self._stream_problem = ""  # the last problem while the stream was open (said with later samples)
        # Room for the largest UDP payload: a datagram is read whole, and a refusal says its size.
        self._datagram = bytearray(65_535)
        self._pending: tuple[Sample, int, Sample | None] | None = None  # the newest, its arrival, the one before
        self._last: Sample | None = None  # the newest sample taken
        self._sent_before: tuple[float, int] | None = None  # the last sample's sent_s and arrival, for their pace
        self._sent_off = 0  # samples in a row whose sent_s has not kept pace with their arrival
        self._due_ns = 0  # when the next sample may go to ``target``
        self._next_log_ns = 0  # when a new problem may be logged
        self._taken = 0  # the loop's target count when last looked at
        self._loop_latency_ns: collections.deque[int] = collections.deque(maxlen=KEPT_LATENCIES)
        self._age_ns: collections.deque[int] = collections.deque(maxlen=KEPT_LATENCIES)
        self._arrived_ns: collections.deque[int] = collections.deque(maxlen=KEPT_LATENCIES)

    @property
    def endpoints(self) -> dict[str, str | None]:
        """Where samples are taken: ``zmq`` (connect a PUSH socket) and ``udp`` (HOST:PORT or None)."""
        udp = None
        if self._udp is not None:
            host, port = self._udp.getsockname()[:2]
            udp = f"{host}:{port}"
        return {"zmq": self.endpoint, "udp": udp}

    def view(self) -> dict[str, Any]:
        """The counters, the rate of samples taken over the last second (Hz), and
        percentiles (ms) of ``loop_latency`` (arrival here → the loop cycle whose set-points
        carry it) and ``age`` (the sender's time → arrival; meaningful only when the sender
        stamps its samples with this host's CLOCK_MONOTONIC, as tools/bench_stream.py does)."""
        now = time.monotonic_ns()
        c = self.counters
        return {"running": self.running, "stream": self._counted, "received": c.received, "malformed": c.malformed,
                "out_of_order": c.out_of_order, "other_sender": c.other_sender, "no_stream": c.no_stream,
                "coalesced": c.coalesced, "forwarded": c.forwarded, "clamped": c.clamped, "loop_behind": c.loop_behind,
                "failed": c.failed, "last_problem": c.last_problem,
                "rate_hz": self._rate_hz(now),
                "loop_latency_ms": _percentiles(self._loop_latency_ns), "age_ms": _percentiles(self._age_ns)}

    def _rate_hz(self, now_ns: int) -> int:
        """Samples taken over the last second; when every arrival kept is that recent, more
        came than are kept: the rate they arrived at."""
        arrived = list(self._arrived_ns)
        recent = sum(1 for t in arrived if now_ns - t <= 1_000_000_000)
        if recent == len(arrived) == self._arrived_ns.maxlen and arrived[-1] > arrived[0]:
            return round((len(arrived) - 1) * 1e9 / (arrived[-1] - arrived[0]))
        return recent

    @property
    def running(self) -> bool:
        """Whether the thread takes samples (started and not ended)."""
        return self._thread.is_alive()

    def _release(self) -> None:
        self._close_monitor()  # before the socket it monitors
        if self._udp is not None:
            self._udp.close()

    def _close_monitor(self) -> None:
        if not self._monitor.closed:  # close() may come more than once
            self._socket.disable_monitor()
            self._monitor.close()

    # -- the thread ------------------------------------------------------------------------

    def _run(self) -> None:
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        poller.register(self._monitor, zmq.POLLIN)
        if self._udp is not None:
            poller.register(self._udp.fileno(), zmq.POLLIN)
        while not self._stopping.is_set():
            wait_ms = POLL_MS
            if self._pending is not None:  # rounded up: a wait rounded down would spin until the time is due
                wait_ms = max(0, -((time.monotonic_ns() - self._due_ns) // 1_000_000))
            ready = dict(poller.poll(wait_ms))
            try:
                self._watch_loop()  # first: samples that follow a stream_open's reply count for the new stream
            except Exception as error:  # the controller's view, in this process: logged, and read again next wake
                self._failed("reading the loop's stream failed", error)
            self._read()
            self._forward_if_due()
            if self._monitor in ready:  # rare: looked at only when it has something
                self._watch_connections()

    def _watch_connections(self) -> None:
        """Say each ZeroMQ sender's connection that closed while a stream was open."""
        while self._monitor.poll(0):
            recv_monitor_message(self._monitor)  # EVENT_DISCONNECTED: the only event asked for
            if self._stream is not None:
                self._problem(f"a ZeroMQ sender's connection to stream {self._stream} closed: the sender ended, or "
                              f"sent a message over {MAX_MESSAGE_BYTES} bytes, whose connection ZeroMQ closes unread "
                              "(what it queued meanwhile is lost, and the stream may time out); keep each message "
                              "one sample")

    def _forward_if_due(self) -> None:
        if self._pending is None:
            return
        now_ns = time.monotonic_ns()
        if now_ns >= self._due_ns:
            self._forward()
            # The next is due a period after this one was due (the wake-up may have been
            # late), or, when the thread was idle or fell behind, a period after this
            # hand-over: timed once it is done, so the next never comes sooner (a hand-over
            # held up a while, then the next right on time, were less than a period apart).
            due_ns = self._due_ns + self._period_ns
            self._due_ns = due_ns if due_ns > now_ns else time.monotonic_ns() + self._period_ns

    def _read(self) -> None:
        """Read what arrived, up to :data:`MAX_PER_WAKE` a socket; a target due meanwhile
        goes on at once (reading a flood on a busy host can take longer than a stream's timeout)."""
        for _ in range(MAX_PER_WAKE):
            try:
                frames = self._socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                break
            if self._from_the_streams_sender(ZEROMQ, frames):
                self._taken_or_counted(frames, ZEROMQ)
            self._forward_if_due()
        if self._udp is None:
            return
        for _ in range(MAX_PER_WAKE):
            try:
                size, sender = self._udp.recvfrom_into(self._datagram)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as error:  # e.g. ICMP errors reported on the socket: not a sample
                self._problem(f"UDP receive failed: {error}")
                break
            datagram = [bytes(self._datagram[:size])]
            if self._from_the_streams_sender(sender, datagram):
                self._taken_or_counted(datagram, sender)
            self._forward_if_due()

    def _from_the_streams_sender(self, sender: Any, frames: list[bytes]) -> bool:
        """Whether the message of ``frames`` from ``sender`` (a UDP address (host, port), or
        :data:`ZEROMQ`) is the open stream's. Two senders (a second program sending to the
        same port, a stray sample numbered far ahead, a ZeroMQ sender beside a UDP one) would
        steer the platform between their poses, or take the stream over: the first sender to
        send :data:`SENDER_DATAGRAMS` of the last :data:`SENDER_WINDOW` samples is the
        stream's, and from then on each message from another is counted ``other_sender`` and
        dropped, from its first. What another sent before the sender was found goes: its
        numbers no longer rank the sender's (one datagram numbered 99999 had every later
        sample of the sender dropped as out of order, and the stream timed out heading for
        its pose; one ZeroMQ message did the same to a UDP stream, found from outside). A UDP
        sender that opens a socket per datagram is never found (:data:`SENDER_WINDOW`):
        nothing of it is dropped. Only a well-formed sample counts towards finding the
        sender (three malformed datagrams from a stray program, sent first, made it the
        sender, found from outside). Without a stream open, nothing is dropped here (they
        are counted ``no_stream``)."""
        if self._stream is None or sender == self._sender:
            return True
        if self._sender is None:
            if not _well_formed(frames):
                return True  # counted malformed where it is taken
            self._recent_senders.append(sender)
            if self._recent_senders.count(sender) < SENDER_DATAGRAMS:
                return True
            self._sender = sender
            if self._last_from != sender:  # the newest sample taken is another's: the sender's next goes on at once
                self._last_sequence = self._last = self._pending = None
            return True
        self._problem(f"samples from {_name(sender)} dropped: {_name(self._sender)} is this stream's sender, and the "
                      "platform would swing between their poses or follow a stray sample; stop the other, or close "
                      "the stream (stream_close) and open one for it")
        self.counters.received += 1
        self.counters.other_sender += 1
        return False

    def _taken_or_counted(self, frames: list[bytes], sender: Any) -> None:
        """Take the message of ``frames`` (a datagram is one) from ``sender`` (a UDP
        address, or :data:`ZEROMQ`), or count it as malformed, whatever goes wrong."""
        try:
            self._take(frames, sender)
        except Exception as error:  # a sample no check foresaw must not end the thread
            self._failed("a message could not be taken", error)
            self.counters.malformed += 1

    def _take(self, frames: list[bytes], sender: Any) -> None:
        received_ns = time.monotonic_ns()
        c = self.counters
        c.received += 1
        try:
            if len(frames) != 1:
                raise MalformedSample(f"a sample is a ZeroMQ message of one frame, this one has {len(frames)}")
            sample = decode(frames[0])
        except MalformedSample as error:
            self._problem(f"malformed sample: {error}")
            c.malformed += 1
            return
        if self._stream is None:
            self._no_stream()
            return
        if sample.sequence is None:  # numbered after the last taken, of either form: the newest
            if self._last_sequence == LAST_SEQUENCE:  # none is above it: every sample after would be dropped
                self._problem(f"the stream's sequence has reached {LAST_SEQUENCE}, the largest: a line without one "
                              "cannot be numbered after it; open a new stream (stream_close, then stream_open)")
                c.out_of_order += 1
                return
            sample = Sample((self._last_sequence or 0) + 1, received_ns / 1e9, sample.pose)
        elif self._last_sequence is not None and sample.sequence <= self._last_sequence:
            self._problem(f"sample {sample.sequence} is not above the last one taken ({self._last_sequence}): dropped "
                          "as reordered or duplicated (a sender that restarted its count needs a new stream: "
                          "stream_close, then stream_open; or a second sender is sending)")
            c.out_of_order += 1
            return
        else:
            self._age_ns.append(received_ns - round(sample.sent_s * 1e9))
            self._check_sent_clock(sample.sent_s, received_ns)
        self._last_sequence = sample.sequence
        self._arrived_ns.append(received_ns)
        if self._pending is not None:
            c.coalesced += 1
        # The sample before goes along: the stream's velocity is between the last two samples
        # sent, not the last two forwarded (two equal poses in a row mean at rest there).
        self._pending, self._last, self._last_from = (sample, received_ns, self._last), sample, sender

    def _check_sent_clock(self, sent_s: float, received_ns: int) -> None:
        """Say (``last_problem``) when ``sent_s`` does not keep pace with the samples'
        arrival, :data:`SENT_CLOCK_SAMPLES` in a row: in milliseconds, or constant. The
        velocity between two samples is taken from it, so such a stream was followed as if
        at rest at each target, lagging and stop-and-go, and nothing said why."""
        before, self._sent_before = self._sent_before, (sent_s, received_ns)
        if before is None or received_ns - before[1] < _ARRIVAL_PACE_NS:
            return
        arrival_s = (received_ns - before[1]) / 1e9
        low, high = SENT_CLOCK_BAND
        paced = low <= (sent_s - before[0]) / arrival_s <= high
        self._sent_off = 0 if paced else self._sent_off + 1
        if self._sent_off >= SENT_CLOCK_SAMPLES:
            self._problem(f"sent_s advanced {sent_s - before[0]:.6g} s between samples that arrived {arrival_s:.3g} s "
                          f"apart ({self._sent_off} in a row): sent_s is the sender's clock in seconds (not "
                          "milliseconds, not a constant): the velocity between samples is taken from it, and the "
                          "platform follows this stream as if at rest at each sample")

    def _watch_loop(self) -> None:
        """Follow the loop's stream: a new one resets the counters; each target it took
        gives a latency."""
        progress = self._progress()
        stream = progress.stream if progress is not None else None
        if stream != self._stream:
            if stream is not None:
                self.counters = StreamCounters()
                self._last_sequence = None
                self._recent_senders.clear()
                self._sender = self._last = self._last_from = None
                self._sent_before, self._sent_off = None, 0
                self._stream_problem = ""
                self._loop_latency_ns.clear()
                self._age_ns.clear()
                self._arrived_ns.clear()
                self._taken = 0
                self._counted = stream
            self._stream = stream
            self._pending = None
        if progress is not None and progress.targets != self._taken and progress.latency_ns is not None:
            self._taken = progress.targets
            self._loop_latency_ns.append(progress.latency_ns)

    def _forward(self) -> None:
        (sample, received_ns, before), self._pending = self._pending, None  # type: ignore[misc]
        assert sample.sequence is not None and sample.sent_s is not None
        try:
            result = self._target(sample.pose, sample.sequence, sample.sent_s, received_ns,
                                  None if before is None or before.sent_s is None else (before.pose, before.sent_s))
        except Exception as error:  # the controller's, in this process: the loop brakes if no target follows
            self._failed(f"target {sample.sequence} could not be handed to the loop", error)
            self.counters.failed += 1
            return
        if result.dropped:
            self.counters.loop_behind += 1
        elif result.sent:
            if result.clamped and result.goal is not None:
                self._problem(_held_short(sample, result.goal))
            if result.joining is not None:
                mm, deg = result.joining
                self._problem(f"sample {sample.sequence} is {mm:.1f} mm and {deg:.2f}° from the platform: beyond "
                              f"{JOIN_DISTANCE[0]:g} mm or {degrees(JOIN_DISTANCE[3]):g}° the stream is joined as a "
                              "step, at rest, not followed at its speed; move the platform to the stream's first pose "
                              "before stream_open (hexactl cue does)")
            self.counters.forwarded += 1
            self.counters.clamped += result.clamped
        else:
            self._no_stream()

    def _no_stream(self) -> None:
        """A well-formed sample with no stream open: counted, and said, for a sender (PUSH or
        UDP: nothing comes back to it) may go on "driving" a platform whose stream ended."""
        ended = " (the last one ended: telemetry's last_stream says why)" if self._counted is not None else ""
        # What went wrong while it was open stays in view: these samples would replace it within a cycle.
        before = f"; the last problem while it was open: {self._stream_problem}" if self._stream_problem else ""
        self._problem(f"samples arrive with no stream open{ended}: they move nothing; stream_open to stream "
                      f"again{before}")
        self.counters.no_stream += 1

    def _failed(self, what: str, error: Exception) -> None:
        """A failure no check foresaw: named in ``last_problem``, logged with its traceback."""
        self._problem(f"{what}: {type(error).__name__}: {error}", error)

    def _problem(self, problem: str, error: Exception | None = None) -> None:
        """``problem`` becomes ``last_problem``; it is logged when it is new, at most once
        every :data:`LOG_INTERVAL_S` (a sender alternating two bad messages cannot flood the log).
        Said before the count that goes with it: a reader that sees the count sees why."""
        now_ns = time.monotonic_ns()
        if problem != self.counters.last_problem and now_ns >= self._next_log_ns:
            self._next_log_ns = now_ns + round(LOG_INTERVAL_S * 1e9)
            if error is None:
                log.warning("stream input: %s", problem)
            else:
                log.error("stream input: %s", problem, exc_info=error)
        self.counters.last_problem = problem
        if self._stream is not None:
            self._stream_problem = problem


def _held_short(sample: Sample, goal: Sequence[float]) -> str:
    """Why the platform is not where ``sample`` asks (mm, deg): held at ``goal``, the nearest
    reachable pose on the way to it. Counted alone, a platform held on a limit looked as if it
    followed (found from outside: 255 clamped, the status otherwise normal)."""
    gap = [abs(a - b) for a, b in zip(sample.pose, goal)]
    turn = max(min(g % 360.0, 360.0 - g % 360.0) for g in gap[3:])
    held = ", ".join(f"{value:.1f}" for value in goal)
    return (f"sample {sample.sequence} is out of reach (a hardware or soft limit): the platform is held at "
            f"({held}) mm and deg, the nearest reachable pose on the way, {max(gap[:3]):.1f} mm and {turn:.2f}° short "
            "of it; hexactl check with the sample's pose names the limit")


def _percentiles(values_ns: collections.deque[int]) -> dict[str, float] | None:
    values = sorted(list(values_ns))
    if not values:
        return None
    pick = lambda q: values[min(len(values) - 1, int(q * len(values)))] / 1e6  # noqa: E731
    return {"p50": pick(0.5), "p99": pick(0.99), "max": values[-1] / 1e6, "count": len(values)}


def _well_formed(frames: list[bytes]) -> bool:
    """Whether ``frames`` are a sample: one frame that :func:`decode` takes."""
    try:
        return len(frames) == 1 and decode(frames[0]) is not None
    except MalformedSample:
        return False


def _name(sender: Any) -> str:
    """``sender`` as ``last_problem`` names it: ``ZeroMQ``, or ``UDP HOST:PORT``."""
    if sender == ZEROMQ:
        return ZEROMQ
    host, port = sender[:2]
    return f"UDP {host}:{port}"
