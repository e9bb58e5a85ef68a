"""The control loop's link to the service's API process: commands in, reports out.

Why a second process: in CPython every thread of a process shares one GIL, so the API's
work (JSON, pydantic validation, planning a move along hundreds of IK samples, a
calibration dry run, the telemetry's JSON) delays the loop's wake-up and stretches its
cycles whenever it holds the lock (BENCHMARKS.md has the loop's lateness with the API
busy in the same process and in its own). The API and everything it does run
in a process of their own (:mod:`hexactl.application.api_process`); what crosses is small:

- **commands** (API → loop): the immutable :mod:`hexactl.control.commands` objects the
  facade builds after planning and validating, pickled, one message each, on a pipe;
- **reports** (loop → API): the loop's :class:`~hexactl.control.host.LoopReport`
  (snapshot, statistics, health, the data recorder's rows) on another pipe, every
  ``interval_s`` (at most :data:`REPORT_INTERVAL_S`; the service matches it to its telemetry
  rate) and at once when a command's verdict is new, so that replies do not wait for it.
  Publishing is the loop thread's largest cost after the cycle itself (pickling the
  snapshot): one report per cycle would double it. A report may be dropped, the recorder's rows
  may not: they are taken from the recorder only for a report the pipe takes whole.
  (The built-in simulator's instrument has a port of its own:
  :mod:`hexactl.application.simulator`.)
- **heartbeats** (API → loop): an empty frame on the command pipe each time the API's
  socket thread, the one that carries out ``estop``, wakes (at least every 0.1 s), at
  most one per :data:`HEARTBEAT_INTERVAL_S`. A frozen API process (stopped, swapped out, a C call holding its GIL) cannot
  pass on an E-stop; the loop's end then hears nothing and, past ``silence_s``, has the
  loop brake any motion to rest (:class:`~hexactl.control.commands.CommandLinkSilent`)
  instead of running on unattended for as long as the motion lasts.

Loop side, :class:`LoopExchange`: the loop thread calls it in its slack (see
:class:`~hexactl.control.loop.ControlLoop`). It takes at most
:data:`MAX_COMMANDS_PER_EXCHANGE` complete commands from the pipe into the core's inbox
and writes the report (pickled), never
waiting: both pipe ends are non-blocking, and a report the pipe has no room for is
dropped. Nothing it meets is allowed to raise into the loop: a message that does not
unpickle to a command is counted and dropped.

API side, :class:`RemoteLoop`: a :class:`~hexactl.control.host.LoopHost` whose snapshot
is the latest report a receiver thread has read, and whose ``submit`` writes to the
command pipe, never waiting either: what the pipe has no room for waits in the process
and is written on as the loop's reports come (a loop that stopped reading, its process
stopped or hung, would otherwise hold up the thread that answers ``estop``); a stream's
target is dropped instead, and while a few wait unread in the pipe. When the loop's
process ends, the host reports the loop as failed.

Both ends are this program's own processes (spawned by the service, pipes inherited),
so pickle is the right encoding: nothing else can write to these pipes.
"""

from __future__ import annotations

import array
import fcntl
import logging
import os
import pickle
import struct
import termios
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from multiprocessing.connection import Connection

from hexactl.control import commands as cmd
from hexactl.control.core import CoreSnapshot
from hexactl.control.host import LoopReport, LoopThread
from hexactl.control.recorder import Row

REPORT_INTERVAL_S = 0.01
"""The longest time between two reports: how old the API's view of the loop (``status``,
telemetry) may be, besides a report dropped. Verdicts do not wait for it."""

MAX_ROWS_PER_REPORT = 64
"""Recorder rows per report at most: bounds the loop's pickling; a backlog (after reports
that did not fit) drains at this many per report."""

HEARTBEAT_INTERVAL_S = 0.05
"""The least time between two heartbeats (a busy socket thread wakes far more often than
it needs to be heard): a twentieth of the default silence limit
(:attr:`~hexactl.control.config.SupervisionConfig.command_silence_s`)."""

MAX_COMMANDS_PER_EXCHANGE = 8
"""Commands taken per exchange: bounds the loop's slack work when many arrive at once."""

SUPERSEDED_UNREAD_BYTES = 1024
"""A command the next one replaces (a stream's target, some 250 to 400 bytes) is dropped
while this much waits unread in the command pipe: a loop held up that long would read them
stale, and an E-stop sent meanwhile would wait behind them, :data:`MAX_COMMANDS_PER_EXCHANGE`
a cycle, once it runs again. Less than an exchange's worth."""

_READ_CHUNK_BYTES = 1 << 16
_READ_PER_CALL_BYTES = 1 << 20  # bounds one exchange's reading; the rest waits in the pipe
_HEADER = struct.Struct("!i")  # multiprocessing.Connection's frame header (frames below 2 GiB)

STATS_MAX_AGE_S = 0.25
"""Published percentiles are at most this old (a sort of the statistics window)."""

log = logging.getLogger("hexactl.loop_link")


class _FrameReader:
    """Non-blocking reads of length-prefixed frames (``multiprocessing.Connection``'s
    framing: a 4-byte big-endian signed length, then the bytes) from a pipe's read end.
    A frame whose bytes have not all arrived waits in the buffer for the next call."""

    def __init__(self, fd: int) -> None:
        os.set_blocking(fd, False)
        self._fd = fd
        self._buffer = bytearray()
        self.closed = False
        """True once the writer's end is closed and everything it wrote has been taken, or
        the stream is :attr:`corrupt`."""
        self.corrupt: str | None = None
        """Why the stream cannot be read on (a header no writer of ours sends); it is then
        closed: nothing after a broken frame boundary can be trusted to be a frame."""

    def frames(self, limit: int) -> list[bytes]:
        """At most ``limit`` complete frames; never waits (reads at most
        :data:`_READ_PER_CALL_BYTES` per call)."""
        read = 0
        while not self.closed and read < _READ_PER_CALL_BYTES:
            try:
                chunk = os.read(self._fd, _READ_CHUNK_BYTES)
            except BlockingIOError:
                break
            except OSError:
                chunk = b""
            if not chunk:
                self.closed = True
            read += len(chunk)
            self._buffer += chunk
        frames = []
        buffer = self._buffer
        while len(frames) < limit and len(buffer) >= _HEADER.size:
            (size,) = _HEADER.unpack_from(buffer)
            if size < 0:  # multiprocessing frames ≥ 2 GiB as -1 and a longer header; ours are far smaller
                self.corrupt = f"a frame header of length {size}"
                self.closed = True
                buffer.clear()
                break
            if len(buffer) < _HEADER.size + size:
                break
            frames.append(bytes(buffer[_HEADER.size:_HEADER.size + size]))
            del buffer[:_HEADER.size + size]
        return frames


class _FrameWriter:
    """Non-blocking writes of length-prefixed frames to a pipe's write end. Frames the pipe
    has no room for wait, in order, to be finished by later calls (a writer that would
    rather drop checks :meth:`flush` before it offers)."""

    def __init__(self, fd: int) -> None:
        os.set_blocking(fd, False)
        self._fd = fd
        self._pending: deque[memoryview] = deque()
        self.closed = False
        """True once the reader's end is closed (or :meth:`close` was called)."""

    def offer(self, payload: bytes) -> bool:
        """Write ``payload`` as one frame, as much of it as fits behind what waits; the
        rest waits. False if the reader is gone (nothing taken)."""
        if self.closed:
            return False
        self._pending.append(memoryview(_HEADER.pack(len(payload)) + payload))
        self.flush()
        return not self.closed

    def flush(self) -> bool:
        """Write what waits, as far as the pipe takes it; True when nothing waits."""
        pending = self._pending
        while pending and not self.closed:
            try:
                written = os.write(self._fd, pending[0])
            except BlockingIOError:
                return False
            except OSError:  # EPIPE: the reader is gone
                self.close()
                break
            pending[0] = pending[0][written:]
            if not pending[0]:
                pending.popleft()
        return not pending and not self.closed

    def unread(self) -> int:
        """Bytes written to the pipe that its reader has not taken yet (FIONREAD)."""
        count = array.array("i", [0])
        fcntl.ioctl(self._fd, termios.FIONREAD, count)
        return count[0]

    def close(self) -> None:
        """Write nothing more (before the descriptor is closed: its number may be reused)."""
        self.closed = True
        self._pending.clear()


class LoopExchange:
    """The loop side of the link; install as the loop's ``exchange`` and :meth:`start`.

    Nothing in it waits: no lock, no blocking read or write (a lock or a pipe shared with
    a thread of lower priority, or with the API's process, would make the loop wait for
    that one's turn on the CPU: priority inversion). Commands are read and reports written
    as far as the pipes allow without waiting; a report the pipe has no room for is
    dropped (the next one follows within ``interval_s``).

    ``silence_s``: once the API has been heard (a heartbeat or a command), nothing from it
    for this long has the loop brake a motion to rest (a
    :class:`~hexactl.control.commands.CommandLinkSilent`; a
    :class:`~hexactl.control.commands.CommandLinkHeard` when it is heard again); None:
    no watch. :meth:`expect_silence` ends the watch (the service stops the API).

    ``rejected``: messages that were not commands (a bug if ever non-zero);
    ``reports_dropped``: reports the pipe had no room for.
    """

    def __init__(self, thread: LoopThread, commands: Connection, reports: Connection,
                 interval_s: float = REPORT_INTERVAL_S, silence_s: float | None = None) -> None:
        self._thread = thread
        self._commands = commands  # kept open: the reader uses its descriptor
        self._reports = reports
        self._reader = _FrameReader(commands.fileno())
        self._writer = _FrameWriter(reports.fileno())
        self._interval_ns = round(min(interval_s, REPORT_INTERVAL_S) * 1e9)
        self._next_report_ns = 0
        self._outcomes_published: tuple[cmd.Outcome, ...] | None = None
        self._silence_ns = None if silence_s is None else round(silence_s * 1e9)
        self._heard_ns: int | None = None  # when the API was last heard (None: not yet)
        self._silent = False  # the loop has been told of the present silence
        self.rejected = 0
        self.reports_dropped = 0

    @property
    def commands_open(self) -> bool:
        """False once the API process has closed its end (or died) and every command it
        sent has been taken, or once its stream is :attr:`corrupt`."""
        return not self._reader.closed

    @property
    def corrupt(self) -> str | None:
        """Why the command stream was closed as unreadable (None: it was not)."""
        return self._reader.corrupt

    @property
    def silent_s(self) -> float:
        """How long the API has not been heard from (s; 0 before it first was, or once
        :meth:`expect_silence` was called). Any thread may read it."""
        heard_ns = self._heard_ns
        return 0.0 if heard_ns is None or self._silence_ns is None else (time.monotonic_ns() - heard_ns) / 1e9

    @property
    def silent(self) -> bool:
        """Whether the API has been silent past ``silence_s`` and the loop was told so (until
        it is heard again). Any thread may read it."""
        return self._silent

    def expect_silence(self) -> None:
        """Stop watching for the API's silence: it is being stopped (any thread)."""
        self._silence_ns = None

    def start(self) -> LoopExchange:
        """Publish the first report; returns self."""
        self._next_report_ns = time.monotonic_ns() + self._interval_ns
        self._publish()
        return self

    def __call__(self) -> None:
        """The loop's slack work: take waiting commands, watch for silence, publish when due."""
        frames = self._reader.frames(MAX_COMMANDS_PER_EXCHANGE)
        now = time.monotonic_ns()
        for data in frames:
            if not data:  # a heartbeat
                continue
            try:
                command = pickle.loads(data)
            except Exception:  # noqa: BLE001 - nothing may raise into the loop
                command = None
            if isinstance(command, cmd.Command):
                self._thread.submit(command)
            else:
                self.rejected += 1
        self._watch_silence(now, heard=bool(frames))
        if now >= self._next_report_ns or self._thread.snapshot.outcomes is not self._outcomes_published:
            self._next_report_ns = now + self._interval_ns
            self._publish()
        else:
            self._writer.flush()

    def _watch_silence(self, now_ns: int, heard: bool) -> None:
        silence_ns, heard_ns = self._silence_ns, self._heard_ns
        if heard:
            if self._silent and silence_ns is not None and heard_ns is not None:
                self._thread.submit(cmd.CommandLinkHeard(0, silent_s=(now_ns - heard_ns) / 1e9))
            self._silent = False
            self._heard_ns = now_ns
        elif (silence_ns is not None and heard_ns is not None and not self._silent
              and now_ns - heard_ns > silence_ns):
            self._silent = True
            self._thread.submit(cmd.CommandLinkSilent(0, silent_s=(now_ns - heard_ns) / 1e9))

    def close(self) -> None:
        """Close both ends (after the loop has stopped)."""
        self._writer.close()
        self._commands.close()
        self._reports.close()

    def _publish(self) -> None:
        if not self._writer.flush():  # the previous report is still unfinished: do not pickle this one
            self.reports_dropped += 1
            return
        # The writer is free: offer() takes the whole frame now, so the rows taken are sent.
        report = replace(self._thread.report(STATS_MAX_AGE_S),
                         recorded=tuple(self._thread.take_recorded(MAX_ROWS_PER_REPORT)))
        if not self._writer.offer(pickle.dumps(report, protocol=pickle.HIGHEST_PROTOCOL)):
            self.reports_dropped += 1
            return
        self._outcomes_published = report.snapshot.outcomes


class RemoteLoop:
    """The API side of the link: a :class:`~hexactl.control.host.LoopHost` for the facade.

    Construction waits (at most ``first_report_timeout_s``) for the first report.

    ``observe`` (the receiver thread; it must not raise): called with each report's snapshot.

    :raises ConnectionError: if no report arrives in time or the loop's end is closed
    """

    def __init__(self, commands: Connection, reports: Connection, first_report_timeout_s: float = 10.0,
                 observe: Callable[[CoreSnapshot], None] | None = None) -> None:
        self._commands = commands  # kept open: the writer uses its descriptor
        self._writer = _FrameWriter(commands.fileno())
        self._observe = observe
        self._reports = reports
        self._send_lock = threading.Lock()  # held only around non-blocking writes
        self._sent_at = -HEARTBEAT_INTERVAL_S  # monotonic s: the last frame sent
        self._gone: str | None = None
        self._recorded: deque[Row] = deque()
        try:
            if not reports.poll(first_report_timeout_s):
                raise ConnectionError(f"no report from the control loop within {first_report_timeout_s:g} s")
            self._latest: LoopReport = self._received(reports.recv_bytes())
            self._received_at = time.monotonic()
        except (EOFError, OSError) as error:
            raise ConnectionError(f"the control loop's link is closed: {error!r}") from None
        self._receiver = threading.Thread(target=self._receive, name="hexactl-loop-link", daemon=True)
        self._receiver.start()

    @property
    def snapshot(self) -> CoreSnapshot:
        return self._latest.snapshot

    def report(self, stats_max_age_s: float) -> LoopReport:
        """The latest report (its percentiles are at most :data:`STATS_MAX_AGE_S` old
        whatever ``stats_max_age_s`` asks), with how long ago it arrived
        (``stats.report_age_s``: a loop whose process is stopped or hung sends none, and its
        last report would otherwise read as current); once the link is gone, the loop is
        reported not running and failed."""
        report = self._latest
        report = replace(report, stats=replace(report.stats, report_age_s=time.monotonic() - self._received_at))
        if self._gone is not None:
            return replace(report, running=False, failure=report.failure or self._gone)
        return report

    def submit(self, command: cmd.Command) -> bool:
        """Write ``command`` to the pipe, as much as it takes now; the rest waits for the
        loop to read (finished as its reports come, by the receiver thread). Never waits
        for the loop: a loop that stopped reading must not hold up this process, whose
        socket thread answers ``estop`` and ``status``. A command the next one replaces
        (:attr:`~hexactl.control.commands.Command.superseded`: a stream's target) is dropped
        rather than kept waiting, so that a stream to a stopped loop does not pile up here,
        and while :data:`SUPERSEDED_UNREAD_BYTES` wait unread, nor in the pipe ahead of an E-stop.
        False when it was dropped, or the link is closed."""
        data = pickle.dumps(command, protocol=pickle.HIGHEST_PROTOCOL)
        with self._send_lock:
            if command.superseded and (not self._writer.flush() or self._writer.unread() >= SUPERSEDED_UNREAD_BYTES):
                return False
            taken = self._writer.offer(data)
            if not taken:
                self._gone = self._gone or "the control loop's link is closed"
            self._sent_at = time.monotonic()
            return taken

    def heartbeat(self) -> None:
        """Tell the loop this process runs (an empty frame), unless something was sent
        within :data:`HEARTBEAT_INTERVAL_S` (that told it already). Never waits: skipped
        while another thread sends, or while commands wait for room in the pipe (a loop
        that does not read is not listening for heartbeats either)."""
        if time.monotonic() - self._sent_at < HEARTBEAT_INTERVAL_S or not self._send_lock.acquire(blocking=False):
            return
        try:
            if self._writer.flush():
                self._writer.offer(b"")
                self._sent_at = time.monotonic()
        finally:
            self._send_lock.release()

    def take_recorded(self) -> list[Row]:
        """The recorder's rows received and not taken yet, oldest first (one taker)."""
        recorded = self._recorded
        return [recorded.popleft() for _ in range(len(recorded))]

    def estop_now(self) -> None:
        """Nothing: the actuators are reachable from the loop's process only; the queued
        E-stop command is carried out within a cycle."""
        return None

    def close(self) -> None:
        """Close the command pipe: the loop side sees its end, then closes the report pipe,
        which ends the receiver. Commands still waiting for room in the pipe are dropped."""
        with self._send_lock:
            self._writer.close()
            self._commands.close()

    def _receive(self) -> None:
        reports = self._reports
        while True:
            try:
                data = reports.recv_bytes()
            except (EOFError, OSError):
                self._gone = "the control loop's process closed the link"
                return
            self._latest = self._received(data)
            self._received_at = time.monotonic()
            self._finish_commands()

    def _finish_commands(self) -> None:
        """Write on what waits of the commands: a report says the loop ran, so it has read
        (the loop takes commands, then reports, in the same slack)."""
        if self._send_lock.acquire(blocking=False):  # else the holder flushes
            try:
                self._writer.flush()
            finally:
                self._send_lock.release()

    def _received(self, data: bytes) -> LoopReport:
        """The report in ``data``, its recorder rows moved to :meth:`take_recorded`'s queue."""
        report: LoopReport = pickle.loads(data)
        if self._observe is not None:
            try:
                self._observe(report.snapshot)
            except Exception:  # an observer's bug must not end the receiver (the API would see a frozen loop)
                log.exception("observing the loop's report failed")
        if report.recorded:
            self._recorded.extend(report.recorded)
            report = replace(report, recorded=())
        return report
