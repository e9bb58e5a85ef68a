"""The telemetry socket: a PUB sending one record per period from its own thread.

Each message is a single frame ``telemetry <json>`` (the topic, a space, a
:class:`~hexactl.adapters.api.messages.Telemetry` record), so that a subscriber can
set ``zmq.CONFLATE`` and always read the newest record: CONFLATE does not work with
multipart messages.

The record is encoded with the stdlib's JSON: at telemetry rates a faster encoder
(orjson) would save too little to be worth a dependency.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import zmq

from hexactl.adapters.api.protocol import DEFAULT_TELEMETRY_RATE_HZ, TOPIC, check_telemetry_rate
from hexactl.adapters.api.security import CurveServer
from hexactl.adapters.api.socket_thread import SocketThread
from hexactl.adapters.api.wire import encode

_SEND_HIGH_WATER_MARK = 100  # records queued per slow subscriber before PUB drops them

MAX_SUBSCRIPTION_BYTES = 1024
"""``zmq.MAXMSGSIZE`` of the telemetry socket, whose only incoming messages are
subscriptions (a flag byte and a topic; hexactl's subscribers send ``telemetry ``) and
the handshake's (CURVE's INITIATE is some 300 bytes): ZeroMQ closes the connection of a
subscriber that sends a longer one, unread. ZeroMQ held each subscription in memory, grown
many times over (one of 300 MB took the API's process past 4 GB)."""

log = logging.getLogger(__name__)


def telemetry_message(record: dict[str, Any]) -> bytes:
    """The single-frame message carrying ``record``."""
    return TOPIC + encode(record)


class TelemetryPublisher(SocketThread):
    """Publish ``record()`` at ``rate_hz`` on a PUB bound to ``endpoint`` (``tcp://HOST:*``
    picks a free port) from its own thread, between :meth:`start` and :meth:`close`.

    ``record`` runs in the publisher's thread and should be cheap (what it takes is the
    record's lateness, and it shares the GIL with the process's command server); an
    exception from it is logged (first occurrence and then every thousandth) and that
    period is skipped.

    :raises ValueError: ``rate_hz`` outside what :func:`~hexactl.adapters.api.protocol.check_telemetry_rate` takes
    :raises zmq.ZMQError: the endpoint is malformed or in use
    """

    def __init__(
        self,
        context: zmq.Context,
        endpoint: str,
        record: Callable[[], dict[str, Any]],
        rate_hz: float = DEFAULT_TELEMETRY_RATE_HZ,
        curve: CurveServer | None = None,
    ) -> None:
        self._record = record
        self._period_s = 1.0 / check_telemetry_rate(rate_hz)
        self._failures = 0
        super().__init__(context, zmq.PUB, endpoint, name="hexactl-telemetry",
                         options={zmq.SNDHWM: _SEND_HIGH_WATER_MARK, zmq.MAXMSGSIZE: MAX_SUBSCRIPTION_BYTES},
                         curve=curve)

    def _run(self) -> None:
        deadline = time.monotonic()
        while True:
            deadline += self._period_s
            delay = deadline - time.monotonic()
            if delay < 0:  # fell behind (a long pause): restart the grid instead of bursting
                deadline, delay = time.monotonic(), 0.0
            if self._stopping.wait(delay):
                return
            self._publish_once()

    def _publish_once(self) -> None:
        try:
            message = telemetry_message(self._record())
        except Exception:
            self._failures += 1
            if self._failures % 1000 == 1:
                log.exception("telemetry record failed (%d times so far)", self._failures)
            return
        try:
            self._socket.send(message, zmq.NOBLOCK)
        except zmq.ZMQError as error:  # PUB drops rather than blocks; this is a closed context
            log.warning("telemetry not sent: %s", error)
