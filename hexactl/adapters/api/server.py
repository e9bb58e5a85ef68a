"""The command socket: a ROUTER served by its own thread, one reply per request.

REQ and DEALER clients both work: the reply goes back with the request's envelope
(:func:`~hexactl.adapters.api.wire.split_envelope`). Whatever arrives, malformed or
oversized or multipart, gets exactly one reply, and nothing a client sends stops the
thread: a handler exception becomes an ``internal_error`` reply and is logged.

Threading (:class:`~hexactl.adapters.api.socket_thread.SocketThread`): the socket belongs
to the server thread after :meth:`ApiServer.start`. It sleeps in ``zmq.Poller.poll`` and
wakes on requests or every :data:`POLL_INTERVAL_MS` to see whether it should stop.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import zmq

from hexactl.adapters.api.messages import Request
from hexactl.adapters.api.security import CurveServer
from hexactl.adapters.api.socket_thread import SocketThread
from hexactl.adapters.api.wire import (
    MAX_REQUEST_BYTES,
    TRANSPORT_MAX_BYTES,
    ApiError,
    ErrorCode,
    decode_request,
    encode,
    error_reply,
    ok_reply,
    split_envelope,
)

DEFAULT_API_ENDPOINT = "tcp://127.0.0.1:5555"

POLL_INTERVAL_MS = 100
"""How often the idle server thread wakes to check for shutdown."""

_BATCH = 64  # requests answered per wake before polling again

Handler = Callable[[Request], dict[str, Any]]
"""Carries out a request: returns the reply's fields beyond v/id/ok, or raises
:class:`~hexactl.adapters.api.wire.ApiError`."""

log = logging.getLogger(__name__)


def answer(body: list[bytes], handle: Handler) -> bytes:
    """The encoded reply to the request frames ``body`` (envelope removed). Never raises."""
    request_id = None
    try:
        if not body:
            raise ApiError(ErrorCode.INVALID_REQUEST, "empty request: no frame after the envelope")
        if len(body) != 1:
            size = sum(len(frame) for frame in body)
            if size > MAX_REQUEST_BYTES:
                raise ApiError(ErrorCode.TOO_LARGE, f"request of {size} bytes; the limit is {MAX_REQUEST_BYTES}")
            raise ApiError(ErrorCode.INVALID_REQUEST, f"a request is one frame of JSON, got {len(body)} frames")
        request = decode_request(body[0])
        request_id = request.id
        reply = ok_reply(request_id, **handle(request))
    except ApiError as error:
        reply = error_reply(request_id if request_id is not None else error.request_id, error.code, error.message, error.details)
    except Exception as error:  # a bug in a handler must not end the service: log it, say so
        log.exception("request %r failed", request_id)
        reply = error_reply(request_id, ErrorCode.INTERNAL_ERROR, f"internal error: {type(error).__name__}: {error}")
    try:
        return encode(reply)
    except ValueError as error:  # a NaN in a handler's reply
        log.error("reply to %r not encodable: %s", request_id, error)
        return encode(error_reply(request_id, ErrorCode.INTERNAL_ERROR, "internal error: the reply held a non-finite number"))


class ApiServer(SocketThread):
    """Serve ``handle`` on a ROUTER bound to ``endpoint`` (``tcp://HOST:*`` picks a free port);
    :meth:`close` stops the thread within :data:`POLL_INTERVAL_MS` and closes the socket.

    :raises zmq.ZMQError: the endpoint is malformed or in use
    """

    def __init__(
        self,
        context: zmq.Context,
        endpoint: str,
        handle: Handler,
        curve: CurveServer | None = None,
    ) -> None:
        self._handle = handle
        super().__init__(context, zmq.ROUTER, endpoint, name="hexactl-api",
                         options={zmq.MAXMSGSIZE: TRANSPORT_MAX_BYTES}, curve=curve)

    def _run(self) -> None:
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        while not self._stopping.is_set():
            if not poller.poll(POLL_INTERVAL_MS):
                continue
            for _ in range(_BATCH):
                try:
                    frames = self._socket.recv_multipart(zmq.NOBLOCK)
                except zmq.Again:
                    break
                envelope, body = split_envelope(frames)
                try:
                    # ROUTER never blocks on send: it drops replies to peers that are gone or full.
                    self._socket.send_multipart([*envelope, answer(body, self._handle)], zmq.NOBLOCK)
                except zmq.ZMQError as error:
                    log.warning("reply not sent: %s", error)
