"""The command socket: a ROUTER whose thread admits requests and a worker thread that
carries them out, one reply per request.

REQ and DEALER clients both work: the reply goes back with the request's envelope
(:func:`~hexactl.adapters.api.wire.split_envelope`). Whatever arrives, malformed or
oversized or multipart, gets exactly one reply, and nothing a client sends stops the
threads: a handler exception becomes an ``internal_error`` reply and is logged.

Threading. The **socket thread** owns the ROUTER (ZeroMQ sockets are not thread-safe)
and never runs a slow handler. For each request it:

- answers a request that cannot be decoded at once (its error);
- carries out ``estop``, ``stop`` and ``abort`` at once, ahead of everything queued
  (they only hand a command to the loop and wait a cycle or two for its verdict), after
  discarding every queued motion request (:data:`CANCELLED_BY_STOP`) from every client,
  and then those ZeroMQ had received but this thread not yet read, each answered
  ``cancelled``: what was asked before a stop must not run after it. A motion request
  the worker is planning meanwhile is refused by the loop as a stale plan if planned
  before the stop was carried out; if it got through all the same, the worker stops the
  platform again after it and answers ``cancelled``;
- queues anything else for a **worker thread**: the :data:`QUERY_COMMANDS` (snapshots:
  ``status``, ``events``, ``geometry``, ``record_status``) for the query worker unless their client has
  a command waiting or being handled (then behind it, so that what it asks after its
  commands reflects them), the rest for the command worker; each has one queue per client
  (the ROUTER's routing identity), served round-robin, bounded per client and in all
  (``busy`` beyond). So another client's plan that takes seconds (a long sequence or
  wave) never holds up an operator's ``status``.

Each request goes to its handler with its **sender**, for people (:func:`sender_of`): the
name its client gave its connection, where it connected from, and with CURVE the name of
its key; the commands it sets off carry it, and the loop's events name it.

A worker takes requests in turn, answers ``expired`` for one whose deadline
(:func:`request_deadline`: ``deadline_ms``, ``expires_at``) has passed, else runs the
handler with the absolute deadline (the loop refuses a motion command past it). Its
replies reach the socket thread through an inproc PUSH→PULL pair the socket thread polls
with the ROUTER (a PUSH per worker: ZeroMQ sockets are not thread-safe).

A watchdog: when a worker has been inside one handler longer than
``handler_timeout_s``, the socket thread logs an error naming the request and calls
``on_stuck`` (the API process ends itself: :mod:`hexactl.application.api_process`). Until
then, and after, the socket thread goes on answering stops and refusals.
"""

from __future__ import annotations

import json
import logging
import os
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zmq

from hexactl.adapters.api.messages import Request, StopRequest
from hexactl.adapters.api.protocol import (
    CLIENT_NAME_PROPERTY,
    MAX_CLIENT_NAME,
    MAX_DEADLINE_MS,
    MAX_REQUEST_BYTES,
    PROTOCOL_VERSION,
    TRANSPORT_MAX_BYTES,
)
from hexactl.adapters.api.security import CurveServer
from hexactl.adapters.api.socket_thread import SocketThread
from hexactl.adapters.api.wire import (
    ApiError,
    ErrorCode,
    decode_request,
    encode,
    error_reply,
    ok_reply,
    split_envelope,
)

POLL_INTERVAL_MS = 100
"""How often the idle threads wake to check for shutdown (and the watchdog its bound)."""

URGENT_COMMANDS = frozenset({"estop", "stop", "abort"})
"""Carried out on the socket thread as they arrive, ahead of every queued request."""

CANCELLED_BY_STOP = frozenset({"move", "jog", "play", "resume", "leg_lock", "leg_unlock", "load_calibration",
                               "rollback_calibration", "stream_open", "wave"})
"""Queued requests an urgent command discards: everything that would set the platform
moving or change its motion or calibration. ``enable`` is not among them (it holds the
pose the platform is at, and is refused while an E-stop is latched), nor are queries."""

QUERY_COMMANDS = frozenset({"status", "events", "geometry", "record_status"})
"""Snapshots of the service, answered by a worker of their own in milliseconds: a monitor
asking ``status`` while another client's long plan is under way gets its answer, not a
time-out that reads as a service gone."""

MAX_QUEUED_PER_CLIENT = 32
"""Requests one client may have waiting. :class:`~hexactl.adapters.api.client.HexactlClient`
has one in flight; a DEALER pipelining a batch (poses to validate) rarely needs more,
and one client must not fill the whole queue."""

MAX_UNREAD_REPLIES = 4 * MAX_QUEUED_PER_CLIENT
"""Replies kept for a client that has not read them (beyond what the sockets buffer);
later ones are dropped. ZeroMQ's default, 1000, let one that never read hold a gigabyte of
``read_file`` replies. Room for a reading client's :data:`MAX_QUEUED_PER_CLIENT` and its
``busy`` replies besides: ZeroMQ counts a reply unread until the client's side says, in
batches of half this bound, that it took it."""

MAX_QUEUED = 256
"""Requests waiting for one worker from all clients together beyond which a client is
refused ``busy`` if it holds its share of them or more (this over the clients with some
waiting). Planning a move or validating a pose takes tens of milliseconds, so a full queue
is seconds of work: what waits longer would outlive the client library's default 5 s
timeout, so it is refused at once instead. A client below its share is still taken, up to
:data:`MAX_QUEUED_CEILING`: found from outside, eight clients of 32 each refused every
other client's every command (an operator's ``reset``, ``frames``) but the stops."""

MAX_QUEUED_CEILING = 2 * MAX_QUEUED
"""Requests waiting for one worker from all clients together beyond which every client is refused."""

DEFAULT_HANDLER_TIMEOUT_S = 120.0
"""The watchdog's default bound on one request's handling, s. The slowest legitimate
request stays below it: a plan gives up at
:data:`~hexactl.control.planning.PLANNING_BUDGET_S`, half of it. Stops never wait for the
worker, so a slow request holds up only other slow requests, never the platform's safety."""

WORKER_JOIN_S = 2.0
"""How long :meth:`ApiServer.close` waits for the worker to finish the request it is in."""

_BATCH = 64  # messages taken from a socket per wake before polling again
_TRANSPORT_DRAIN_LIMIT = 4096  # bounds the reading after an urgent command under a flood that never ends

Handler = Callable[[Request, int | None, str | None], dict[str, Any]]
"""Carries out a request by its absolute deadline (monotonic ns, None: none) for its
sender (:func:`sender_of`; None: the API itself): returns the reply's fields beyond
v/id/ok, or raises :class:`~hexactl.adapters.api.wire.ApiError`."""

_IPC_PEER = re.compile(r"localhost:(\d+):(\d+):(\d+)")
"""ZeroMQ's ``Peer-Address`` of an IPC connection: the peer's uid, gid and pid (SO_PEERCRED)."""

log = logging.getLogger(__name__)


def decode_body(body: list[bytes]) -> Request:
    """The request in the frames ``body`` (envelope removed); :class:`ApiError` says what is wrong."""
    if not body:
        raise ApiError(ErrorCode.INVALID_REQUEST, "empty request: no frame after the envelope")
    if len(body) != 1:
        size = sum(len(frame) for frame in body)
        if size > MAX_REQUEST_BYTES:
            raise ApiError(ErrorCode.TOO_LARGE, f"request of {size} bytes; the limit is {MAX_REQUEST_BYTES}")
        raise ApiError(ErrorCode.INVALID_REQUEST, f"a request is one frame of JSON, got {len(body)} frames")
    return decode_request(body[0])


def sender_of(frame: zmq.Frame) -> str:
    """Who sent the request ``frame`` came with, for people: the name its client gave its
    connection (:data:`~hexactl.adapters.api.protocol.CLIENT_NAME_PROPERTY`, made printable
    and cut to :data:`~hexactl.adapters.api.protocol.MAX_CLIENT_NAME`), then what the
    client cannot choose: the peer's IP address over TCP, its process and user over IPC,
    and with CURVE the name of its key (:class:`~hexactl.adapters.api.security.CurveServer`)."""
    name = _connection_property(frame, CLIENT_NAME_PROPERTY)[:MAX_CLIENT_NAME]
    name = "".join(c if c.isprintable() else "?" for c in name) or "an unnamed client"
    peer = _connection_property(frame, "Peer-Address")
    local = _IPC_PEER.fullmatch(peer)
    key = _connection_property(frame, "User-Id")
    where = ", ".join(part for part in (f"pid {local[3]}, uid {local[1]}" if local else peer, key and f"key {key}") if part)
    return f"{name} ({where})" if where else name


def _connection_property(frame: zmq.Frame, name: str) -> str:
    """The connection's property ``name`` ("" when it has none)."""
    try:
        return frame.get(name)
    except UnicodeDecodeError as error:  # pyzmq reads properties as UTF-8; a client may send any bytes
        return error.object.decode("utf-8", "replace")
    except zmq.ZMQError:  # not set on this connection
        return ""


def carry_out(request: Request, handle: Handler, deadline_ns: int | None, sender: str | None) -> bytes:
    """The encoded reply to ``request``, carried out by ``handle``. Never raises."""
    return encoded(request.id, reply_to(request, handle, deadline_ns, sender))


def reply_to(request: Request, handle: Handler, deadline_ns: int | None, sender: str | None) -> dict[str, Any]:
    """The reply to ``request``, carried out by ``handle``. Never raises."""
    try:
        return ok_reply(request.id, **handle(request, deadline_ns, sender))
    except ApiError as error:
        return error_reply(request.id, error.code, error.message, error.details)
    except Exception as error:  # a bug in a handler must not end the service: log it, say so
        log.exception("request %r failed", request.id)
        return error_reply(request.id, ErrorCode.INTERNAL_ERROR, f"internal error: {type(error).__name__}: {error}")


def encoded(request_id: Any, reply: dict[str, Any]) -> bytes:
    """``reply`` encoded; an ``internal_error`` reply instead if it holds a non-finite number."""
    try:
        return encode(reply)
    except ValueError as error:  # a NaN in a handler's reply
        log.error("reply to %r not encodable: %s", request_id, error)
        return encode(error_reply(request_id, ErrorCode.INTERNAL_ERROR, "internal error: the reply held a non-finite number"))


def describe(request: Request) -> str:
    """``cmd (id …)`` for logs and messages."""
    return f"{request.cmd} (id {json.dumps(request.id)[:100]})"


@dataclass(frozen=True, slots=True)
class _Queued:
    envelope: list[bytes]
    request: Request
    deadline_ns: int | None  # monotonic
    deadline: str  # which of the request's deadlines that is, for an expired reply
    sender: str


def request_deadline(request: Request, received_ns: int, now: tuple[int, float]) -> tuple[int | None, str]:
    """When ``request``, received at ``received_ns`` (monotonic ns), is too late to carry
    out (monotonic ns; None: never), and which deadline that is, for people: its
    ``deadline_ms`` from its receipt, or its ``expires_at`` on this host's wall clock,
    whichever comes first. ``now`` is one instant on both clocks (monotonic ns,
    time.time()), read together: the wall clock's deadline is carried over to the
    monotonic one from it, so a thread preempted after the receipt does not shorten it.
    ``deadline_ms`` alone counts from the receipt, which a frozen or starved API process
    delays: a move its client had given up on ran when the process resumed (found from
    outside); ``expires_at`` is the sender's own time.

    :raises ApiError: ``invalid_request``: ``expires_at`` more than the longest deadline
        (an hour) ahead, a time in ms, or not this host's epoch: no bound at all
    """
    now_ns, now_s = now
    deadlines: list[tuple[int, str]] = []
    if request.deadline_ms is not None:
        deadlines.append((received_ns + round(request.deadline_ms * 1e6), f"its deadline_ms ({request.deadline_ms:g})"))
    if request.expires_at is not None:
        if (left_s := request.expires_at - now_s) > MAX_DEADLINE_MS / 1000.0:
            raise ApiError(ErrorCode.INVALID_REQUEST, f"{request.cmd}: expires_at {request.expires_at:.17g} is "
                           f"{left_s:.6g} s after this host's time {now_s:.3f}, beyond the longest deadline, an hour: "
                           "a Unix time in s, as time.time() gives it (not ms)", request_id=request.id)
        late = (f"; it arrived {-left_s * 1e3:.0f} ms after it: held up on its way, or the sender's clock is behind "
                "this host's (keep them together: NTP)") if left_s < 0 else ""
        deadlines.append((now_ns + round(left_s * 1e9),
                          f"its expires_at ({request.expires_at:.3f}, by this host's clock{late})"))
    return min(deadlines, default=(None, ""))


_STOP_AFTER_RACE = StopRequest(v=PROTOCOL_VERSION, id=None, cmd="stop")


def _cancelled(request: Request, cause: str) -> bytes:
    return encode(error_reply(request.id, ErrorCode.CANCELLED,
                              f"{request.cmd} cancelled, not carried out: {cause} arrived while it was queued"))


class _RoundRobin:
    """Requests waiting for one worker: a queue per client (routing identity) in arrival
    order, the clients served in turn; bounded per client and in all. ``discards`` counts
    :meth:`discard` calls, so that a worker can tell whether one happened while it handled
    what it took."""

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._queues: dict[bytes, deque[_Queued]] = {}
        self._turns: deque[bytes] = deque()
        self._handling: bytes | None = None  # the client whose request the worker took last, until done
        self.queued = 0
        self.discards = 0

    def holds(self, client: bytes) -> bool:
        """Whether ``client`` has a request here, waiting or being handled."""
        with self._ready:
            return client in self._queues or client == self._handling

    def done(self) -> None:
        """The worker has answered what it took."""
        with self._ready:
            self._handling = None

    def put(self, client: bytes, item: _Queued) -> str | None:
        """Queue ``item`` from ``client``; None, or why it is refused (``busy``)."""
        with self._ready:
            mine = len(self._queues.get(client, ()))
            if mine >= MAX_QUEUED_PER_CLIENT:
                return f"{mine} requests queued from this client; wait for replies before sending more"
            if self.queued >= MAX_QUEUED_CEILING:
                return (f"{self.queued} requests queued from {len(self._queues)} clients, the most the service "
                        "keeps; wait a moment and send it again")
            if self.queued >= MAX_QUEUED and mine >= (share := max(1, MAX_QUEUED // len(self._queues))):
                return (f"{self.queued} requests queued from {len(self._queues)} clients, {mine} of them from this "
                        f"one (its share: {share}); wait for replies before sending more")
            if not mine:
                self._queues[client] = deque()
                self._turns.append(client)
            self._queues[client].append(item)
            self.queued += 1
            self._ready.notify()
        return None

    def take(self, stopping: threading.Event) -> tuple[_Queued, int] | None:
        """The next request in turn and the discards so far; None once ``stopping``."""
        with self._ready:
            while not self._turns:
                if stopping.is_set():
                    return None
                self._ready.wait(POLL_INTERVAL_MS / 1000)
            if stopping.is_set():
                return None
            client = self._turns.popleft()
            queue = self._queues[client]
            item = queue.popleft()
            if queue:
                self._turns.append(client)
            else:
                del self._queues[client]
            self.queued -= 1
            self._handling = client
            return item, self.discards

    def discard(self, commands: frozenset[str]) -> list[_Queued]:
        """Remove and return every queued request for one of ``commands``."""
        with self._ready:
            discarded: list[_Queued] = []
            for client in list(self._turns):
                queue = self._queues[client]
                kept = deque(item for item in queue if item.request.cmd not in commands)
                discarded += [item for item in queue if item.request.cmd in commands]
                if kept:
                    self._queues[client] = kept
                else:
                    del self._queues[client]
                    self._turns.remove(client)
            self.queued -= len(discarded)
            self.discards += 1
            return discarded

    def wake(self) -> None:
        with self._ready:
            self._ready.notify_all()


class _Worker:
    """A worker thread's parts: its ``lane`` of requests, its PUSH of replies to the socket
    thread, and what it is handling since when (monotonic ns), for the watchdog."""

    def __init__(self, name: str, lane: _RoundRobin, context: zmq.Context, replies: str) -> None:
        self.name = name
        self.lane = lane
        self.replies = context.socket(zmq.PUSH)
        self.replies.linger = 0
        self.replies.sndhwm = 2 * MAX_QUEUED
        self.replies.connect(replies)
        self.thread: threading.Thread | None = None
        self.in_handler: tuple[int, str] | None = None

    def describe(self) -> str:
        return self.in_handler[1] if self.in_handler is not None else "no request"


class ApiServer(SocketThread):
    """Serve ``handle`` on a ROUTER bound to ``endpoint`` (``tcp://HOST:*`` picks a free
    port), as the module describes. ``on_stuck(description)`` is called once when the
    worker has spent ``handler_timeout_s`` in one request, or if the socket thread fails
    (None: only logged).
    :meth:`close` stops both threads (the worker within :data:`WORKER_JOIN_S`, else it is
    left behind: it is a daemon) and closes the sockets. ``worker_niceness``: the worker
    thread's ``nice`` (the socket thread keeps the process's). ``on_wake()``: called by the
    socket thread each time it wakes, at least every :data:`POLL_INTERVAL_MS` (the loop
    link's heartbeat: the thread that carries out ``estop`` runs); it must not block.

    :raises zmq.ZMQError: the endpoint is malformed or in use
    """

    def __init__(
        self,
        context: zmq.Context,
        endpoint: str,
        handle: Handler,
        curve: CurveServer | None = None,
        *,
        handler_timeout_s: float = DEFAULT_HANDLER_TIMEOUT_S,
        on_stuck: Callable[[str], None] | None = None,
        worker_niceness: int = 0,
        on_wake: Callable[[], None] | None = None,
    ) -> None:
        self._handle = handle
        self._on_wake = on_wake
        self._worker_niceness = worker_niceness
        self._handler_timeout_ns = round(handler_timeout_s * 1e9)
        self._on_stuck = on_stuck
        # MANDATORY: a reply dropped past MAX_UNREAD_REPLIES raises, so that the log says why.
        super().__init__(context, zmq.ROUTER, endpoint, name="hexactl-api",
                         options={zmq.MAXMSGSIZE: TRANSPORT_MAX_BYTES, zmq.SNDHWM: MAX_UNREAD_REPLIES,
                                  zmq.ROUTER_MANDATORY: 1}, curve=curve)
        replies = f"inproc://hexactl-api-replies-{id(self)}"
        # Never full while the socket thread drains it: at most MAX_QUEUED replies a worker are owed.
        self._replies_in = context.socket(zmq.PULL)
        self._replies_in.linger = 0
        self._replies_in.rcvhwm = 4 * MAX_QUEUED
        self._replies_in.bind(replies)
        self._commands = _RoundRobin()  # discards: the urgent commands, compared across a motion request
        self._queries = _RoundRobin()
        self._workers = [_Worker("hexactl-api-worker", self._commands, context, replies),
                         _Worker("hexactl-api-queries", self._queries, context, replies)]
        self._reported: tuple[int, str] | None = None  # the stuck handling already reported
        self._not_reading: set[bytes] = set()  # routing ids of the clients whose replies are being dropped

    @property
    def _queued(self) -> int:
        """Requests waiting for either worker."""
        return self._commands.queued + self._queries.queued

    def start(self) -> None:
        super().start()
        for worker in self._workers:
            worker.thread = threading.Thread(target=self._work, args=(worker,), name=worker.name, daemon=True)
            worker.thread.start()

    def close(self) -> None:
        super().close()  # the socket thread has stopped and the ROUTER is closed
        for worker in self._workers:
            worker.lane.wake()
        for worker in self._workers:
            if worker.thread is not None and worker.thread.is_alive():
                worker.thread.join(WORKER_JOIN_S)
                if worker.thread.is_alive():
                    log.warning("%s is still in %s: left behind", worker.name, worker.describe())
            # Closed even under a worker left behind: it is in a handler, not in ZeroMQ, and a
            # send on a closed socket raises there (caught) instead of holding up shutdown.
            worker.replies.close()
        self._replies_in.close()

    # -- the socket thread -------------------------------------------------------------

    def _run(self) -> None:
        """Serve until stopped. Should this thread fail all the same, nothing would be
        answered again, an E-stop included: it ends the process as a stuck worker does."""
        try:
            self._serve()
        except Exception as error:
            log.exception("the API's socket thread failed")
            if self._on_stuck is not None:
                self._on_stuck(f"the API's socket thread failed ({type(error).__name__}: {error}): no request "
                               "would be answered again")

    def _serve(self) -> None:
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        poller.register(self._replies_in, zmq.POLLIN)
        while not self._stopping.is_set():
            ready = dict(poller.poll(POLL_INTERVAL_MS))
            if self._on_wake is not None:
                self._on_wake()
            self._watch()
            if self._replies_in in ready:
                for _ in range(_BATCH):
                    try:
                        self._send(self._replies_in.recv_multipart(zmq.NOBLOCK))
                    except zmq.Again:
                        break
            if self._socket in ready:
                for _ in range(_BATCH):
                    try:
                        frames = self._socket.recv_multipart(zmq.NOBLOCK, copy=False)  # frames: their sender's properties
                    except zmq.Again:
                        break
                    self._admit_guarded(frames)

    def _admit_guarded(self, frames: list[zmq.Frame], stopped_by: str | None = None) -> None:
        """:meth:`_admit`; a defect met in it is that request's, answered ``internal_error``
        and logged: it must not end the thread that reads every request, an E-stop's."""
        try:
            self._admit(frames, time.monotonic_ns(), stopped_by)
        except Exception as error:
            self._internal_error(frames, error)

    def _internal_error(self, frames: list[zmq.Frame], error: Exception) -> None:
        """Log the defect that ``error`` is and answer the request in ``frames`` with it."""
        log.exception("a request could not be handled")
        try:
            envelope, _ = split_envelope([frame.bytes for frame in frames])
            self._send([*envelope, encode(error_reply(None, ErrorCode.INTERNAL_ERROR,
                                                      f"internal error: {type(error).__name__}: {error}"))])
        except Exception:
            log.exception("nor could it be answered")

    def _admit(self, frames: list[zmq.Frame], received_ns: int, stopped_by: str | None = None) -> None:
        """Answer, carry out or queue one request. ``stopped_by``: the urgent command just
        carried out, which cancels a motion request read after it from the transport."""
        envelope, body = split_envelope([frame.bytes for frame in frames])
        try:
            request = decode_body(body)
        except ApiError as error:
            self._send([*envelope, encode(error_reply(error.request_id, error.code, error.message, error.details))])
            return
        if stopped_by is not None and request.cmd in CANCELLED_BY_STOP:
            self._send([*envelope, _cancelled(request, stopped_by)])
            return
        if request.cmd in URGENT_COMMANDS:
            cause = describe(request)
            self._cancel_queued(cause)  # first: the worker must not take one of them meanwhile
            reply = carry_out(request, self._handle, None, sender_of(frames[-1]))
            if stopped_by is None and request.cmd != "estop":
                # Before the reply: what a client sends once it has seen the reply was
                # sent after the stop, and must not be cancelled by it.
                self._cancel_in_transport(cause)
            self._send([*envelope, reply])
            if stopped_by is None and request.cmd == "estop":
                # After it: an E-stop's confirmation does not wait for thousands of requests
                # read (found from outside: 2 to 4 s under a flood, near a client's 5 s
                # timeout, which then says "not confirmed"). A motion sent once it is seen is
                # refused while it is latched anyway: cancelled here, it is carried out neither way.
                self._cancel_in_transport(cause)
            return
        try:
            deadline_ns, deadline = request_deadline(request, received_ns, (time.monotonic_ns(), time.time()))
        except ApiError as error:
            self._send([*envelope, encode(error_reply(error.request_id, error.code, error.message))])
            return
        client = envelope[0]
        # A query waits behind its own client's commands (what it asks after them reflects
        # them), never behind another client's.
        quick = request.cmd in QUERY_COMMANDS and not self._commands.holds(client)
        item = _Queued(envelope, request, deadline_ns, deadline, sender_of(frames[-1]))
        refusal = (self._queries if quick else self._commands).put(client, item)
        if refusal is not None:
            self._send([*envelope, encode(error_reply(request.id, ErrorCode.BUSY, refusal,
                                                      {"limit_per_client": MAX_QUEUED_PER_CLIENT, "limit": MAX_QUEUED,
                                                       "ceiling": MAX_QUEUED_CEILING}))])

    def _cancel_in_transport(self, cause: str) -> None:
        """Cancel the motion requests ZeroMQ had received but this thread not yet read when
        ``cause`` was carried out, and admit the others. They were sent before it, perhaps
        by a client gone since (600 moves, then closed): they must not run after it either."""
        for _ in range(_TRANSPORT_DRAIN_LIMIT):
            try:
                frames = self._socket.recv_multipart(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                return
            self._admit_guarded(frames, stopped_by=cause)

    def _cancel_queued(self, cause: str) -> None:
        """Discard every queued :data:`CANCELLED_BY_STOP` request, answering each ``cancelled``."""
        for item in self._commands.discard(CANCELLED_BY_STOP):
            self._send([*item.envelope, _cancelled(item.request, cause)])

    def _watch(self) -> None:
        for worker in self._workers:
            in_handler = worker.in_handler
            if in_handler is None or in_handler is self._reported:
                continue
            since_ns, what = in_handler
            if time.monotonic_ns() - since_ns > self._handler_timeout_ns:
                self._reported = in_handler
                description = (f"the API worker has been handling {what} for more than "
                               f"{self._handler_timeout_ns / 1e9:g} s: the API is stuck")
                log.error("%s", description)
                if self._on_stuck is not None:
                    self._on_stuck(description)

    def _send(self, frames: list[bytes]) -> None:
        """Never blocks: a reply to a client that is gone, or that has
        :data:`MAX_UNREAD_REPLIES` replies unread, is dropped (the latter said once a run
        of them, in the log)."""
        try:
            self._socket.send_multipart(frames, zmq.NOBLOCK)
        except zmq.Again:
            if frames[0] not in self._not_reading:
                self._not_reading.add(frames[0])
                log.warning("replies to a client dropped: it has %d replies unread (the most kept for one client); "
                            "a client must read its replies", MAX_UNREAD_REPLIES)
            return
        except zmq.ZMQError as error:  # EHOSTUNREACH: the client has gone, as a timed-out one does
            log.debug("reply not sent: %s", error)
        self._not_reading.discard(frames[0])

    # -- the workers ---------------------------------------------------------------------

    def _work(self, worker: _Worker) -> None:
        if self._worker_niceness:  # Linux: a thread's own niceness (its thread id), not the process's
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self._worker_niceness)
        while (taken := worker.lane.take(self._stopping)) is not None:
            item, stops = taken
            request = item.request
            if item.deadline_ns is not None and (late_ns := time.monotonic_ns() - item.deadline_ns) >= 0:
                reply = error_reply(request.id, ErrorCode.EXPIRED,
                                    f"{request.cmd} expired, not carried out: {item.deadline} passed "
                                    f"{late_ns / 1e6:.1f} ms before its turn came; send it again with a longer "
                                    "deadline if it is still wanted")
            else:
                worker.in_handler = (time.monotonic_ns(), describe(request))
                reply = reply_to(request, self._handle, item.deadline_ns, item.sender)
                if request.cmd in CANCELLED_BY_STOP and worker.lane.discards != stops and reply["ok"]:
                    reply = self._stop_after_race(request)
                worker.in_handler = None
            try:
                worker.replies.send_multipart([*item.envelope, encoded(request.id, reply)], zmq.NOBLOCK)
            except zmq.ZMQError as error:  # closed under a worker left behind by close()
                log.warning("reply to %s not sent: %s", describe(request), error)
                return
            finally:
                worker.lane.done()  # after the reply: a query of its client sent before it waits for it

    def _stop_after_race(self, request: Request) -> dict[str, Any]:
        """An urgent command arrived while ``request`` was being planned, and it was still
        handed to the loop, perhaps after the urgent one: stop, so that it does not outlive
        it, and say so."""
        reply_to(_STOP_AFTER_RACE, self._handle, None, f"the API, as {describe(request)} raced a stop")
        return error_reply(request.id, ErrorCode.CANCELLED, f"{request.cmd} cancelled: a stop, abort or estop arrived "
                           "while it was being planned, and the platform was stopped again after it")
