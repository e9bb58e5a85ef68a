"""The dashboard's way to the service: the public ZeroMQ API and telemetry, nothing else.

A :class:`ServiceBridge` follows the telemetry in a thread of its own and hands each
record to the pages' outboxes, serialised once for all of them (newest only, and at most
:data:`TELEMETRY_WINDOW` records a page has not acknowledged: a page that handles them
slowly skips records and falls no further behind than that); it fetches the active geometry
whenever the calibration changes; and it carries the pages' commands to the API, each on
a client of its own in a worker thread, so that a slow command never holds up another.
``estop``, ``stop`` and ``abort`` each have a worker of their own (:class:`UrgentCommand`):
a page that floods the others, or floods one of them, cannot delay another. ``jog`` has one
too, in order: a release must never reach the service before a renewal sent ahead of it.

A page's command has a time to live, counted from when the page sent it, as far as the
dashboard can tell (its ``at``: :class:`~hexactl.adapters.web.app.PageClock`), else from
when the dashboard read it (its :class:`Admission`): the page's own timeout
(:attr:`ServiceBridge.command_timeout_s`, the dashboard's ``--timeout``, which the page is
told in its ``hello``), or for a jog that moves, one deadman period of the service. One
still queued when it is up is never sent: it is answered ``expired``. One sent is given
what is left of it, as the API client's wait and (less its margin) as the request's
``deadline_ms``, so the service refuses it too if it comes late; a ``deadline_ms`` of the
page's own is kept only when shorter. So nothing the page has given up on is carried out
later (found from outside: a move queued behind 12 commands, or behind an API stalled for
17 s, ran after the page had said "timeout"; jog renewals queued during a stall started a
jog after the page had said it was released; and both, held up in a stalled dashboard
before it read them, while their time to live counted from then). What stops motion
(``estop``, ``stop``, ``abort``, a jog's release) has no time to live: carried out late, it
is still wanted.

The dashboard adds no privilege: every command is an API request like any client's, and
the service validates it.

It shows one service and commands one service, and makes sure they are the same: each
telemetry record names its service's ``run``, and whenever a record names a run not yet
compared (at start, after the telemetry was lost, or the service restarted) the API's
``status`` is asked for its own. While they differ (``--api`` and ``--telemetry`` of two
services: found from outside, a page showed rig A enabled while its confirmed E-stop
latched rig B), every command but ``estop``, ``stop`` and ``abort`` is refused
(``two_services``, naming both endpoints) and the pages are told the link is down, with
why. Until the first comparison is answered, commands go as before.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber, deadline_ms
from hexactl.control.config import ControllerConfig

URGENT_COMMANDS = ("estop", "stop", "abort")
"""Commands carried out each on a worker of its own, never queued behind others. None
takes fields."""

COMMAND_WORKERS = 4
"""Worker threads for the other commands (a command waits at most the API timeout)."""

LINK_TIMEOUT_S = 1.0
"""No telemetry for this long: the service is reported unreachable (50 records at the
default rate; it reconnects by itself when the service is back)."""

FAN_OUT_CHUNK = 16
"""Pages handed a message between two turns of the event loop. The fan-out of a record to
every page is cut in chunks so that a command waits behind at most one chunk's sends, not
behind every page's (with 400 pages on a loaded host, a page's E-stop waited behind whole
fan-outs at each of its steps on the loop)."""

JOG_DEADMAN_S: float = ControllerConfig.model_fields["jog_deadman_s"].default
"""A jog's time to live in the dashboard until a jog's reply gives the service's own
deadman (``deadman_s``): the service's default."""

SEND_FLOOR_FRACTION = 0.05
"""A command with less than this fraction of its time to live left is not sent (it is
answered ``expired``): the service could hardly carry it out and answer in what is left."""

UNCOMPARED = object()
"""No run: the telemetry's run compared last, before any comparison and once the telemetry
is lost (not None: an older service's records name none)."""

MAX_RECORD_AGE_S = 60.0
"""A record's age is reported only when the service's clock is this host's (a record
older than this, or from the future, comes from another host's monotonic clock)."""

log = logging.getLogger("hexactl.dashboard")


@dataclass(frozen=True)
class ServiceEndpoints:
    """Where the service is and how to reach it: ``connect(kind, endpoint)`` makes a
    client (with CURVE keys when the service needs them: ``curve``)."""

    api: str
    telemetry: str
    timeout_s: float
    connect: Callable[..., Any]
    curve: bool = False


@dataclass
class Admission:
    """A page's command on its way to a worker: ``cmd``, its ``fields``, the ``client``
    name, and when the page sent it (``received``) and it must be answered by
    (``answer_by``), both ``time.monotonic()``; ``send_by``: not sent from then on.
    ``given_deadline_ms``: the page's own ``deadline_ms``, if it sent one.

    Sent or expired once, by whichever comes first: the worker that takes it
    (:meth:`take`) or the event loop when its time is up (:meth:`expire`)."""

    cmd: str
    fields: dict[str, Any]
    client: str
    received: float
    answer_by: float
    send_by: float
    given_deadline_ms: float | None = None
    state: str = "queued"  # queued, then sent or expired
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def take(self) -> bool:
        """On the worker: whether to send it now (else it is, or has just been, answered ``expired``)."""
        with self._lock:
            if self.state == "queued":
                self.state = "sent" if time.monotonic() < self.send_by else "expired"
            return self.state == "sent"

    def expire(self) -> bool:
        """On the event loop, its time up: whether it was still queued (it is never sent now)."""
        with self._lock:
            if self.state == "queued":
                self.state = "expired"
            return self.state == "expired"

    def request_fields(self, now: float) -> dict[str, Any]:
        """Its fields with the ``deadline_ms`` of what is left of its time at ``now`` (the
        page's own, if shorter)."""
        own = deadline_ms(max(self.answer_by - now, 0.0))
        if self.given_deadline_ms is not None:
            own = min(own, self.given_deadline_ms)
        return {**self.fields, "deadline_ms": own}

    def expired_reply(self) -> dict[str, Any]:
        waited = time.monotonic() - self.received
        return error_reply("expired", f"{self.cmd} expired, not carried out: it waited {waited:.1f} s on its way from "
                           f"the page and in the dashboard for its turn (a link or the dashboard held up, the service "
                           f"slow to answer, or other commands ahead of it), and "
                           f"its time to live was {self.answer_by - self.received:g} s; send it again if it is still "
                           "wanted")


class UrgentCommand:
    """``name`` (an urgent command, no fields) sent by ``request(name, {}, client)`` on a
    thread of its own, one at a time. A press while one is waiting to be sent shares its
    reply (and the client name of the press that made it wait); a press while one is
    being sent waits for the next. So every press is carried out after it was made, and a
    flood of presses costs one request at a time, never a queue."""

    def __init__(self, name: str, request: Callable[[str, dict[str, Any], str], dict[str, Any]]) -> None:
        self.name = name
        self._request = request
        self._worker = ThreadPoolExecutor(1, thread_name_prefix=f"dashboard-{name}")
        self._one_at_a_time = asyncio.Lock()
        self._waiting: asyncio.Task[dict[str, Any]] | None = None

    async def __call__(self, client: str) -> dict[str, Any]:
        if self._waiting is None:
            self._waiting = asyncio.get_running_loop().create_task(self._send(client))
        return await asyncio.shield(self._waiting)

    async def _send(self, client: str) -> dict[str, Any]:
        async with self._one_at_a_time:
            self._waiting = None  # being sent: a press from now on waits for the next
            return await asyncio.get_running_loop().run_in_executor(self._worker, self._request, self.name, {}, client)

    def close(self) -> None:
        self._worker.shutdown(wait=False, cancel_futures=True)


OUTBOX_KINDS = ("link", "geometry", "acked", "telemetry")
"""What an outbox sends a page, in the order it sends what it holds: the link's state, the
geometry that telemetry is drawn with, the page's newest acknowledgement received (so that
the page can time how far behind it is), then the newest record."""

TELEMETRY_WINDOW = 16
"""Telemetry messages a page may have been sent and not yet acknowledged; the newest
waits in its outbox meanwhile. The page acknowledges at least every 8th it handles
(``ACK_EVERY`` in static/app.js, which must stay below this)."""


@dataclass(frozen=True, slots=True)
class Update:
    """A message for a page's outbox: ``kind`` (one of :data:`OUTBOX_KINDS`), its JSON
    ``text`` (but for ``acked``, the same for every page), and for telemetry its ``number``
    (the ``n`` that pages acknowledge)."""

    kind: str
    text: str
    number: int | None = None


class Outbox:
    """A page's messages not yet sent: the newest of each kind only, and no telemetry
    while :data:`TELEMETRY_WINDOW` sent are unacknowledged.

    The same text goes to every page, serialised once by the bridge: at hundreds of pages
    and 50 records a second a serialisation per page kept the event loop busy enough to
    hold an E-stop's reply back for most of a second. A page that does not read (a frozen
    tab, a wedged client) holds at most one message of each kind here: what it missed is
    replaced, never queued. The window bounds what waits beyond here, in the sockets'
    buffers and the browser's: without it a page that handled records more slowly than
    they came (a starved browser on a busy host) fell further behind each second, showing
    a state tens of seconds old as live. Commands' replies do not pass through here: they
    are sent by the command's own task, never dropped."""

    def __init__(self) -> None:
        self._pending: dict[str, Update] = {}
        self._unacknowledged: deque[int] = deque()  # the numbers of telemetry sent, oldest first
        self._changed = asyncio.Event()

    def put(self, update: Update) -> None:
        """On the event loop: ``update`` replaces the one of its kind not yet sent."""
        self._pending[update.kind] = update
        self._changed.set()

    def acknowledge(self, number: int) -> None:
        """On the event loop: the page has handled telemetry message ``number`` and every
        one before it. It is told so (``acked``) behind everything it was sent before: the
        time that takes, on the page's clock alone, is how far behind the page is. The
        message carries this host's clock (``server_ms``, as telemetry's ``sent_ms``): with
        the round trip, a page on another host's clock learns how far its clock is off."""
        while self._unacknowledged and self._unacknowledged[0] <= number:
            self._unacknowledged.popleft()
        self.put(Update("acked", f'{{"type": "acked", "n": {number}, "server_ms": {time.time() * 1000.0:.1f}}}'))

    async def get(self) -> str:
        """The next message's text: the first kind of :data:`OUTBOX_KINDS` held that may go."""
        while (kind := self._next_kind()) is None:
            self._changed.clear()
            await self._changed.wait()
        update = self._pending.pop(kind)
        if update.number is not None:
            self._unacknowledged.append(update.number)
        return update.text

    def _next_kind(self) -> str | None:
        window_open = len(self._unacknowledged) < TELEMETRY_WINDOW
        return next((kind for kind in OUTBOX_KINDS
                     if kind in self._pending and (kind != "telemetry" or window_open)), None)

    def __len__(self) -> int:
        """The messages held, not yet sent."""
        return len(self._pending)


class ServiceBridge:
    """Telemetry and the geometry out to the pages, commands in to the API."""

    def __init__(self, endpoints: ServiceEndpoints) -> None:
        self.endpoints = endpoints
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pages: dict[Outbox, None] = {}  # the pages served (a dict: in the order they came)
        self._news: dict[str, Update] = {}  # the newest update of each kind not yet fanned out
        self._news_came = asyncio.Event()
        self._fan_out: asyncio.Task[None] | None = None
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._urgent = {name: UrgentCommand(name, self._request) for name in URGENT_COMMANDS}
        self._workers = ThreadPoolExecutor(COMMAND_WORKERS, thread_name_prefix="dashboard-command")
        # One jog at a time, in the order sent: on the shared workers a release could overtake
        # the renewals still in flight, and one of those would start the jog again after it.
        self._jog_worker = ThreadPoolExecutor(1, thread_name_prefix="dashboard-jog")
        # The geometry is fetched beside the telemetry, never in its way: an API that does
        # not answer would hold each record back for the request's timeout.
        self._geometry_worker = ThreadPoolExecutor(1, thread_name_prefix="dashboard-geometry")
        self._jog_deadman_s = JOG_DEADMAN_S  # the service's, from its newest jog reply
        self._fetching = threading.Event()
        self._comparing = threading.Event()
        self._run_compared: object = UNCOMPARED  # the telemetry's run the API's was last compared with
        self._two_services: str | None = None  # why, while --api and --telemetry are two services
        self.connected = False
        self.geometry: dict[str, Any] | None = None
        self._geometry_update: Update | None = None  # the geometry message, serialised for new pages
        self._link_message = f"waiting for telemetry from {endpoints.telemetry}"
        self._announced: str | None = None  # the link message the pages were last sent

    # -- life ------------------------------------------------------------------------

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """On ``loop``: start following the telemetry and fanning it out to the pages."""
        self._loop = loop
        self._fan_out = loop.create_task(self._fan_out_news())
        self._thread = threading.Thread(target=self._follow_telemetry, name="dashboard-telemetry", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * LINK_TIMEOUT_S)
        if self._fan_out is not None:
            self._fan_out.cancel()
        for urgent in self._urgent.values():
            urgent.close()
        self._workers.shutdown(wait=False, cancel_futures=True)
        self._jog_worker.shutdown(wait=False, cancel_futures=True)
        self._geometry_worker.shutdown(wait=False, cancel_futures=True)

    @property
    def command_timeout_s(self) -> float:
        """How long a page waits for a command's reply (it is told so in its ``hello``),
        and the dashboard at most, from when the page sent it, to answer it: the
        dashboard's ``--timeout``, s."""
        return self.endpoints.timeout_s

    def hello(self) -> str:
        """The first message to a page: ``{"type": "hello", "command_timeout_ms": …}``."""
        return json.dumps({"type": "hello", "command_timeout_ms": self.command_timeout_s * 1000.0})

    # -- pages -----------------------------------------------------------------------

    def subscribe(self) -> Outbox:
        """On the event loop: a page's outbox of ``link``, ``geometry`` and ``telemetry``
        messages. It starts with the link's state and the geometry, when known."""
        outbox = Outbox()
        outbox.put(self._link())
        if (geometry := self._geometry_update) is not None:
            outbox.put(geometry)
        self._pages[outbox] = None
        return outbox

    def unsubscribe(self, outbox: Outbox) -> None:
        self._pages.pop(outbox, None)

    def _broadcast(self, update: Update) -> None:
        """On the event loop: ``update`` is news for every page; it replaces news of its
        kind not yet fanned out."""
        self._news[update.kind] = update
        self._news_came.set()

    async def _fan_out_news(self) -> None:
        """The news to every page's outbox, the same text to all, :data:`FAN_OUT_CHUNK`
        pages at a time with a turn of the loop between chunks. No page's sending is waited
        for; what comes meanwhile is fanned out next, the newest only."""
        while True:
            await self._news_came.wait()
            self._news_came.clear()
            news, self._news = self._news, {}
            pages = list(self._pages)
            for first in range(0, len(pages), FAN_OUT_CHUNK):
                await asyncio.sleep(0)  # a turn of the loop: what came meanwhile (a command's step) goes first
                for outbox in pages[first:first + FAN_OUT_CHUNK]:
                    for update in news.values():
                        outbox.put(update)

    def _link(self) -> Update:
        two_services = self._two_services
        return Update("link", json.dumps({"type": "link", "connected": self.connected and two_services is None,
                                          "message": two_services or self._link_message}))

    def _announce(self) -> None:
        """On the event loop: the link's state to every page, if it is news to them."""
        link = self._link()
        if link.text != self._announced:
            self._announced = link.text
            self._broadcast(link)

    # -- commands --------------------------------------------------------------------

    async def command(self, cmd: str, fields: dict[str, Any], browser: str | None = None,
                      received: float | None = None) -> dict[str, Any]:
        """The API's reply to ``cmd`` with ``fields``, ok or not; an ``unavailable`` error
        reply when the service does not answer in time, ``expired`` when it was still queued
        here when its time to live was up (never sent), ``invalid_request`` for fields no
        request can carry (an urgent command's, the envelope's, a number not finite). The
        service is told it comes from the dashboard for ``browser`` (its address), so that
        its events say who sent it. Its time to live counts from ``received``, when the
        page sent it as far as the dashboard can tell (``time.monotonic()``; None: now)."""
        received = time.monotonic() if received is None else received
        client = f"dashboard, browser {browser}" if browser else "dashboard"
        if (urgent := self._urgent.get(cmd)) is not None:
            if fields:
                return error_reply("invalid_request", f"{cmd} takes no fields, got {', '.join(sorted(fields))}")
            return await urgent(client)
        if (two_services := self._two_services) is not None:
            return error_reply("two_services", f"{cmd} not sent: {two_services}")
        workers = self._jog_worker if cmd == "jog" else self._workers
        loop = asyncio.get_running_loop()
        given = fields.get("deadline_ms")
        if given is not None and not finite_number(given):
            return error_reply("invalid_request", f"{cmd}: deadline_ms is a finite number of ms, got {given!r}")
        if _is_release(cmd, fields):  # stops a jog: no time to live (as stop), in order behind the renewals
            if given is not None:  # the page's own only when shorter than the dashboard's
                fields = {**fields, "deadline_ms": min(given, deadline_ms(self.command_timeout_s))}
            return await loop.run_in_executor(workers, self._request, cmd, fields, client)
        lifetime_s = self._jog_deadman_s if cmd == "jog" else self.command_timeout_s
        admission = Admission(cmd, {key: value for key, value in fields.items() if key != "deadline_ms"}, client,
                              received, received + lifetime_s, received + lifetime_s * (1.0 - SEND_FLOOR_FRACTION),
                              given)
        carried = loop.run_in_executor(workers, self._carry_out, admission)
        done, _ = await asyncio.wait({carried}, timeout=max(0.0, admission.send_by - time.monotonic()))
        if not done and admission.expire():
            return admission.expired_reply()  # the worker that takes it later passes it by
        reply = await carried
        return admission.expired_reply() if reply is None else reply

    def _carry_out(self, admission: Admission) -> dict[str, Any] | None:
        """On a worker: ``admission`` sent, with what is left of its time, and its reply;
        None if it has expired (the event loop answers it)."""
        if not admission.take():
            return None
        now = time.monotonic()
        reply = self._request(admission.cmd, admission.request_fields(now), admission.client,
                              admission.answer_by - now)
        deadman = reply.get("deadman_s") if admission.cmd == "jog" and reply.get("ok") else None
        if isinstance(deadman, (int, float)) and not isinstance(deadman, bool) and 0.0 < deadman <= MAX_JOG_DEADMAN_S:
            self._jog_deadman_s = float(deadman)
        return reply

    def _request(self, cmd: str, fields: dict[str, Any], client_name: str,
                 timeout_s: float | None = None) -> dict[str, Any]:
        """The API's reply to ``cmd``, waited for ``timeout_s`` (a page's command: what is
        left of its time to live), by default the dashboard's ``--timeout``."""
        endpoints = self.endpoints
        timeout_s = endpoints.timeout_s if timeout_s is None else timeout_s
        if timeout_s <= 0.0:
            return error_reply("expired", f"{cmd} expired, not carried out: its time to live was up before it was sent")
        try:
            with endpoints.connect(HexactlClient, endpoints.api, timeout_s=timeout_s, name=client_name) as client:
                return client.request(cmd, **fields)
        except ServiceUnavailable as error:
            return error_reply("unavailable", str(error))
        except ValueError as error:  # refused by the client before sending
            return error_reply("invalid_request", str(error))

    # -- telemetry -------------------------------------------------------------------

    def _follow_telemetry(self) -> None:
        """The telemetry thread: receive, hand over, notice the link and the calibration."""
        endpoints = self.endpoints
        number = 0  # the telemetry messages' ``n``: from this process, so it goes on across service restarts
        with endpoints.connect(TelemetrySubscriber, endpoints.telemetry) as telemetry:
            while not self._stopping.is_set():
                try:
                    record = telemetry.receive(LINK_TIMEOUT_S)
                except ServiceUnavailable:
                    self._set_link(False, f"no telemetry from {endpoints.telemetry} for {LINK_TIMEOUT_S:g} s: is "
                                   "hexactl serve running? (reconnects by itself)")
                    continue
                received = time.monotonic()
                self._set_link(True, f"telemetry from {endpoints.telemetry}")
                if not self._fetching.is_set() and (
                        self.geometry is None or self.geometry.get("calibration_id") != record.get("calibration_id")):
                    self._fetching.set()
                    self._geometry_worker.submit(self._fetch_geometry)
                if not self._comparing.is_set() and record.get("run") != self._run_compared:
                    self._comparing.set()
                    self._geometry_worker.submit(self._compare_runs, record.get("run"))
                age_s = received - float(record.get("t", received))
                # Stamped here, with the age, not as each page is sent it: one text for
                # every page, and the page's age_ms + (its clock − sent_ms) then also
                # counts the time the record waited in the dashboard.
                number += 1
                message = {"type": "telemetry", "n": number, "record": record, "sent_ms": time.time() * 1000.0,
                           "age_ms": age_s * 1000.0 if 0.0 <= age_s <= MAX_RECORD_AGE_S else None}
                self._call(self._broadcast, Update("telemetry", json.dumps(message), number))

    def _set_link(self, connected: bool, message: str) -> None:
        if connected != self.connected:
            log.info("%s", message)
            if not connected:
                # fetched and compared afresh when the service is back: it may have restarted
                self.geometry = self._geometry_update = None
                self._run_compared = UNCOMPARED
        if (connected, message) != (self.connected, self._link_message):
            self.connected, self._link_message = connected, message
            self._call(self._announce)

    def _compare_runs(self, telemetry_run: str | None) -> None:
        """On the geometry's worker: whether the API answers for the service whose records
        name ``telemetry_run``, by its ``status``'s run; the next record asks again if the
        API does not answer."""
        try:
            reply = self._request("status", {}, "dashboard")
            if not reply.get("ok"):
                log.warning("status, to compare the API's service with the telemetry's: %s",
                            (reply.get("error") or {}).get("message"))
                return
            api_run = reply["status"].get("run")
            endpoints = self.endpoints
            self._two_services = None if api_run == telemetry_run else (
                f"--api {endpoints.api} and --telemetry {endpoints.telemetry} are two different services (run "
                f"{api_run} answers the API, run {telemetry_run} sends the telemetry): the page would show the one "
                "and command the other, so only estop, stop and abort are sent (to the API's service); check --api "
                "and --telemetry")
            if self._two_services is not None:
                log.error("%s", self._two_services)
            self._run_compared = telemetry_run
            self._call(self._announce)
        except Exception as error:  # a worker's exception would go unseen
            log.warning("status, to compare the API's service with the telemetry's: %s: %s", type(error).__name__, error)
        finally:
            self._comparing.clear()

    def _fetch_geometry(self) -> None:
        """On the geometry's worker; the next record asks again if this fails."""
        try:
            reply = self._request("geometry", {}, "dashboard")
            if not reply.get("ok"):
                log.warning("geometry: %s", (reply.get("error") or {}).get("message"))
                return
            self.geometry = drawing_geometry(reply)
            self._geometry_update = Update("geometry", json.dumps({"type": "geometry", "geometry": self.geometry}))
            self._call(self._broadcast, self._geometry_update)
        except Exception as error:  # a worker's exception would go unseen
            log.warning("geometry: %s: %s", type(error).__name__, error)
        finally:
            self._fetching.clear()

    def _call(self, function: Callable[..., None], *arguments: Any) -> None:
        if self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(function, *arguments)


MAX_JOG_DEADMAN_S: float = next(bound.le for bound in ControllerConfig.model_fields["jog_deadman_s"].metadata
                                if hasattr(bound, "le"))
"""The longest deadman a jog reply's ``deadman_s`` is taken for (the service's bound)."""


def _is_release(cmd: str, fields: dict[str, Any]) -> bool:
    """Whether ``cmd`` with ``fields`` is a jog's release: a jog of zero velocity."""
    velocity = fields.get("velocity")
    return (cmd == "jog" and isinstance(velocity, list) and len(velocity) == 6
            and all(type(v) in (int, float) and v == 0 for v in velocity))


def finite_number(value: Any) -> bool:
    """Whether ``value`` is a JSON number that a float holds, finite: not a bool, not NaN
    nor infinite, not an integer of hundreds of digits."""
    try:
        return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
    except OverflowError:  # an int beyond a float's range
        return False


def error_reply(code: str, message: str) -> dict[str, Any]:
    """An error reply as the API's, for what the dashboard answers itself."""
    return {"ok": False, "error": {"code": code, "message": message}}


def drawing_geometry(reply: dict[str, Any]) -> dict[str, Any]:
    """The ``geometry`` reply as the page takes it: the file's keys, with the calibration's
    identity and, at the top, the stroke, the pose envelope and the feature points."""
    geometry = reply["geometry"]
    return {**geometry, "calibration_id": reply["calibration_id"], "source": reply["source"],
            "stroke": geometry["limits"]["stroke"], "pose_min": geometry["limits"]["pose_min"],
            "pose_max": geometry["limits"]["pose_max"], "feature_points": geometry["measurement"]["feature_points"]}
