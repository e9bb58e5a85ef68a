"""The dashboard's way to the service: the public ZeroMQ API and telemetry, nothing else.

A :class:`ServiceBridge` follows the telemetry in a thread of its own and hands each
record to the pages' queues (newest only: a page that draws slowly skips records, it
never falls behind); it fetches the active geometry whenever the calibration changes; and
it carries the pages' commands to the API, each on a client of its own in a worker
thread, so that a slow command never holds up another. ``estop``, ``stop`` and ``abort``
each have a worker of their own (:class:`UrgentCommand`): a page that floods the others,
or floods one of them, cannot delay another.

The dashboard adds no privilege: every command is an API request like any client's, and
the service validates it.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber

URGENT_COMMANDS = ("estop", "stop", "abort")
"""Commands carried out each on a worker of its own, never queued behind others. None
takes fields."""

COMMAND_WORKERS = 4
"""Worker threads for the other commands (a command waits at most the API timeout)."""

LINK_TIMEOUT_S = 1.0
"""No telemetry for this long: the service is reported unreachable (50 records at the
default rate; it reconnects by itself when the service is back)."""

MAX_RECORD_AGE_S = 60.0
"""A record's age is reported only when the service's clock is this host's (a record
older than this, or from the future, comes from another host's monotonic clock)."""

log = logging.getLogger("hexactl.dashboard")


@dataclass(frozen=True)
class ServiceEndpoints:
    """Where the service is and how to reach it: ``connect(kind, endpoint)`` makes a
    client (with CURVE keys when the service needs them)."""

    api: str
    telemetry: str
    timeout_s: float
    connect: Callable[..., Any]


class UrgentCommand:
    """``name`` (an urgent command, no fields) sent by ``request(name, {})`` on a thread of
    its own, one at a time. A press while one is waiting to be sent shares its reply; a
    press while one is being sent waits for the next. So every press is carried out after
    it was made, and a flood of presses costs one request at a time, never a queue."""

    def __init__(self, name: str, request: Callable[[str, dict[str, Any]], dict[str, Any]]) -> None:
        self.name = name
        self._request = request
        self._worker = ThreadPoolExecutor(1, thread_name_prefix=f"dashboard-{name}")
        self._one_at_a_time = asyncio.Lock()
        self._waiting: asyncio.Task[dict[str, Any]] | None = None

    async def __call__(self) -> dict[str, Any]:
        if self._waiting is None:
            self._waiting = asyncio.get_running_loop().create_task(self._send())
        return await asyncio.shield(self._waiting)

    async def _send(self) -> dict[str, Any]:
        async with self._one_at_a_time:
            self._waiting = None  # being sent: a press from now on waits for the next
            return await asyncio.get_running_loop().run_in_executor(self._worker, self._request, self.name, {})

    def close(self) -> None:
        self._worker.shutdown(wait=False, cancel_futures=True)


@dataclass(frozen=True)
class Update:
    """What a page receives: one JSON-able message (see :meth:`ServiceBridge.subscribe`)."""

    message: dict[str, Any]


class ServiceBridge:
    """Telemetry and the geometry out to the pages, commands in to the API."""

    def __init__(self, endpoints: ServiceEndpoints) -> None:
        self.endpoints = endpoints
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pages: set[asyncio.Queue[dict[str, Any]]] = set()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._urgent = {name: UrgentCommand(name, self._request) for name in URGENT_COMMANDS}
        self._workers = ThreadPoolExecutor(COMMAND_WORKERS, thread_name_prefix="dashboard-command")
        self.connected = False
        self.geometry: dict[str, Any] | None = None
        self._link_message = f"waiting for telemetry from {endpoints.telemetry}"
        self._announced: bool | None = None  # the link state the pages were last told

    # -- life ------------------------------------------------------------------------

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._thread = threading.Thread(target=self._follow_telemetry, name="dashboard-telemetry", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * LINK_TIMEOUT_S)
        for urgent in self._urgent.values():
            urgent.close()
        self._workers.shutdown(wait=False, cancel_futures=True)

    # -- pages -----------------------------------------------------------------------

    def subscribe(self) -> asyncio.Queue[dict[str, Any]]:
        """A page's queue of messages: ``link``, ``geometry`` and ``telemetry`` (the newest
        only). It starts with the link's state and the geometry, when known."""
        queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        queue.put_nowait(self._link())
        if self.geometry is not None:
            queue.put_nowait({"type": "geometry", "geometry": self.geometry})
        self._pages.add(queue)
        return queue

    def unsubscribe(self, queue: asyncio.Queue[dict[str, Any]]) -> None:
        self._pages.discard(queue)

    def _broadcast(self, message: dict[str, Any]) -> None:
        """On the event loop: to every page; a telemetry record replaces one not yet sent."""
        for queue in self._pages:
            if message["type"] == "telemetry" and not queue.empty():
                kept = [item for item in _drain(queue) if item["type"] != "telemetry"]
                for item in kept:
                    queue.put_nowait(item)
            queue.put_nowait(message)

    def _link(self) -> dict[str, Any]:
        return {"type": "link", "connected": self.connected, "message": self._link_message}

    # -- commands --------------------------------------------------------------------

    async def command(self, cmd: str, fields: dict[str, Any]) -> dict[str, Any]:
        """The API's reply to ``cmd`` with ``fields``, ok or not; an ``unavailable`` error
        reply when the service does not answer in time, ``invalid_request`` for fields no
        request can carry (an urgent command's, the envelope's, a number not finite)."""
        if (urgent := self._urgent.get(cmd)) is not None:
            if fields:
                return error_reply("invalid_request", f"{cmd} takes no fields, got {', '.join(sorted(fields))}")
            return await urgent()
        return await asyncio.get_running_loop().run_in_executor(self._workers, self._request, cmd, fields)

    def _request(self, cmd: str, fields: dict[str, Any]) -> dict[str, Any]:
        endpoints = self.endpoints
        try:
            with endpoints.connect(HexactlClient, endpoints.api, timeout_s=endpoints.timeout_s) as client:
                return client.request(cmd, **fields)
        except ServiceUnavailable as error:
            return error_reply("unavailable", str(error))
        except ValueError as error:  # refused by the client before sending
            return error_reply("invalid_request", str(error))

    # -- telemetry -------------------------------------------------------------------

    def _follow_telemetry(self) -> None:
        """The telemetry thread: receive, hand over, notice the link and the calibration."""
        endpoints = self.endpoints
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
                if self.geometry is None or self.geometry.get("calibration_id") != record.get("calibration_id"):
                    self._fetch_geometry()
                age_s = received - float(record.get("t", received))
                message = {"type": "telemetry", "record": record, "sent_ms": None,
                           "age_ms": age_s * 1000.0 if 0.0 <= age_s <= MAX_RECORD_AGE_S else None}
                self._call(self._broadcast, message)

    def _set_link(self, connected: bool, message: str) -> None:
        if connected != self.connected:
            log.info("%s", message)
            if not connected:
                self.geometry = None  # fetched afresh when the service is back: it may have restarted
        self.connected, self._link_message = connected, message
        if connected != self._announced:
            self._announced = connected
            self._call(self._broadcast, self._link())

    def _fetch_geometry(self) -> None:
        reply = self._request("geometry", {})
        if not reply.get("ok"):
            log.warning("geometry: %s", (reply.get("error") or {}).get("message"))
            return
        self.geometry = drawing_geometry(reply)
        self._call(self._broadcast, {"type": "geometry", "geometry": self.geometry})

    def _call(self, function: Callable[..., None], *arguments: Any) -> None:
        if self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(function, *arguments)


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


def _drain(queue: asyncio.Queue[dict[str, Any]]) -> list[dict[str, Any]]:
    items = []
    while not queue.empty():
        items.append(queue.get_nowait())
    return items
