"""Python clients of a running ``hexactl serve``: commands and telemetry.

    with HexactlClient("tcp://127.0.0.1:5555") as client:
        client.call("enable")
        client.call("move", pose=[0, 0, 50, 0, 0, 5], duration=2.0)
        print(client.call("status")["status"]["pose_measured"])

    with TelemetrySubscriber("tcp://127.0.0.1:5556") as telemetry:
        record = telemetry.receive(timeout_s=1.0)

Poses are [x, y, z, roll, pitch, yaw] in mm and degrees relative to the zero posture.
"""

from __future__ import annotations

import itertools
import json
import time
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

import zmq

from hexactl.adapters.api.protocol import (
    CLIENT_NAME_PROPERTY,
    DEFAULT_API_ENDPOINT,
    DEFAULT_TELEMETRY_ENDPOINT,
    DEFAULT_TIMEOUT_S,
    MAX_DEADLINE_MS,
    MAX_REQUEST_BYTES,
    PROTOCOL_VERSION,
    TOPIC,
    TRANSPORT_MAX_BYTES,
    default_client_name,
    is_local_endpoint,
)

if TYPE_CHECKING:  # CURVE's modules load only for a client that uses it (see ZmqConnection)
    from hexactl.adapters.api.security import CurveClientKeys

DEADLINE_MARGIN_FRACTION = 0.2
DEADLINE_MARGIN_MIN_MS = 50.0


class ServiceUnavailable(Exception):
    """No reply (or no telemetry) within the timeout: the service is not running there,
    or is unreachable."""


class CommandError(Exception):
    """The service refused or failed a command: ``code`` (snake_case), ``message``, ``details``."""

    def __init__(self, code: str, message: str, details: Any = None) -> None:
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message
        self.details = details


class ZmqConnection:
    """A ZeroMQ socket of ``kind`` connected to ``endpoint``, closed with the object.

    In the process's shared context: a context of its own, left to the garbage collector
    unclosed within a reference cycle (a timed-out request's traceback makes one), is
    finalised before its socket and waits for it for ever, hanging the program."""

    def __init__(self, kind: int, endpoint: str, curve: CurveClientKeys | None, options: dict[int, int | bytes]) -> None:
        self.endpoint = endpoint
        self.curve = curve
        self.socket = zmq.Context.instance().socket(kind)
        self.socket.linger = 0
        for option, value in options.items():
            self.socket.setsockopt(option, value)
        if curve is not None:
            from hexactl.adapters.api.security import secure_client  # zmq.auth: not for a local client

            secure_client(self.socket, curve)
        self.socket.connect(endpoint)

    def close(self) -> None:
        self.socket.close()

    def _unanswered(self, what: str, seconds: float) -> ServiceUnavailable:
        """No ``what`` (an answer, telemetry) within ``seconds``, with its likely causes:
        a service that refuses a CURVE handshake drops it without a word."""
        if self.curve is not None:
            hint = ("; with CURVE, a service that does not know this client's key, or whose public key is not the "
                    "one given as the server's, stays silent: check both keys")
        elif not is_local_endpoint(self.endpoint):
            hint = ("; a service beyond localhost answers only clients with CURVE keys (hexactl: --curve-server and "
                    "--curve-client, or the client file's curve_server and curve_client)")
        else:
            hint = ""
        return ServiceUnavailable(f"no {what} from {self.endpoint} within {seconds:g} s: is `hexactl serve` running "
                                  f"there?{hint}")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None) -> None:
        self.close()


ENVELOPE_FIELDS = frozenset({"v", "id", "cmd"})
"""What every request carries besides its command's fields."""


class HexactlClient(ZmqConnection):
    """Commands to the service at ``endpoint``; one request at a time, not thread-safe.
    ``name`` names this client to the service, for people (its events and log say who sent
    each command by it: :data:`~hexactl.adapters.api.protocol.CLIENT_NAME_PROPERTY`); by
    default ``PROGRAM USER@HOST``; ``""``: none (the service says "an unnamed client").

    A DEALER socket rather than REQ so that a timed-out request leaves the client
    usable: a late reply to it is recognised by its ``id`` and dropped. ``IMMEDIATE``
    so that a request is never queued for a service that is not there yet: a command
    that timed out must not run when the service starts later.

    Every request carries ``deadline_ms`` (unless the caller gives one): ``timeout_s``
    less a margin of 20 % of it, at least 50 ms and at most half of it
    (:func:`deadline_ms`), and ``expires_at``, the same deadline on this host's clock
    (unless the caller gives one). The service carries out nothing after either (it
    answers ``expired``), and the margin lets the answer to a request carried out just
    before it reach this client before it gives up: a request this client timed out on
    never runs later, even when the service reads it late (a frozen API process).
    """

    def __init__(
        self, endpoint: str = DEFAULT_API_ENDPOINT, *, timeout_s: float = DEFAULT_TIMEOUT_S, curve: CurveClientKeys | None = None,
        name: str | None = None,
    ) -> None:
        name = default_client_name() if name is None else name
        # ZeroMQ refuses an empty property: "" leaves the client unnamed.
        metadata = {zmq.METADATA: f"{CLIENT_NAME_PROPERTY}:{name}".encode()} if name else {}
        super().__init__(zmq.DEALER, endpoint, curve, {zmq.IMMEDIATE: 1, **metadata})
        self.timeout_s = timeout_s
        self._ids = itertools.count(1)

    def request(self, cmd: str, /, **fields: Any) -> dict[str, Any]:
        """Send a command and return the whole reply, ok or not. A request the service could
        not read (too large, not JSON) is answered without its ``id``: that error is the reply.

        :raises ValueError: a field is the envelope's (``v``, ``id``, ``cmd``), not finite (NaN
            or infinity) or not JSON-able, or the request is beyond what the service reads
            (:data:`~hexactl.adapters.api.protocol.TRANSPORT_MAX_BYTES`: no reply would come);
            nothing is sent
        :raises ServiceUnavailable: it cannot be sent or no reply arrives within ``timeout_s``
        """
        if envelope := sorted(ENVELOPE_FIELDS & fields.keys()):
            raise ValueError(f"{cmd}: {', '.join(envelope)}: the request's envelope, not a command's field")
        request_id = next(self._ids)
        fields = {"deadline_ms": deadline_ms(self.timeout_s), **fields}
        # The same deadline on this host's clock: deadline_ms counts from the service's receipt,
        # which a frozen service delays past this client's giving up.
        fields.setdefault("expires_at", time.time() + fields["deadline_ms"] / 1000.0)
        try:
            message = json.dumps({"v": PROTOCOL_VERSION, "id": request_id, "cmd": cmd, **fields}, allow_nan=False)
        except ValueError as error:
            raise ValueError(f"{cmd}: the API takes finite numbers only, not NaN or infinity ({error})") from None
        except TypeError as error:
            raise ValueError(f"{cmd}: a field is not a JSON value ({error})") from None
        if (size := len(message.encode())) > TRANSPORT_MAX_BYTES:  # the service would drop it unanswered
            raise ValueError(f"{cmd}: a request of {size} bytes: the API answers {MAX_REQUEST_BYTES} at most, and one "
                             f"beyond {TRANSPORT_MAX_BYTES} it cannot even read to answer; send less")
        deadline = time.monotonic() + self.timeout_s
        unavailable = self._unanswered("answer", self.timeout_s)
        self.socket.sndtimeo = max(1, round(self.timeout_s * 1000))
        try:
            self.socket.send(message.encode())
        except zmq.Again:
            raise unavailable from None
        while True:
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0 or not self.socket.poll(remaining_s * 1000.0):
                raise unavailable
            reply = json.loads(self.socket.recv_multipart()[-1])
            if reply.get("id") == request_id or (reply.get("id") is None and reply.get("ok") is False):
                return reply

    def call(self, cmd: str, /, **fields: Any) -> dict[str, Any]:
        """Send a command; return its reply when ok, else raise :class:`CommandError`
        (and :class:`ServiceUnavailable` on no reply)."""
        reply = self.request(cmd, **fields)
        if not reply.get("ok"):
            error = reply.get("error") or {}
            raise CommandError(error.get("code", "unknown"), error.get("message", ""), error.get("details"))
        return reply


def deadline_ms(timeout_s: float) -> float:
    """The ``deadline_ms`` for a request its sender waits ``timeout_s`` for: the timeout
    less a margin of 20 % of it, at least 50 ms and at most half of it (so the answer
    travels back in time), within the service's bound (:data:`MAX_DEADLINE_MS`)."""
    timeout_ms = timeout_s * 1000.0
    margin_ms = min(max(DEADLINE_MARGIN_MIN_MS, DEADLINE_MARGIN_FRACTION * timeout_ms), timeout_ms / 2)
    return min(timeout_ms - margin_ms, MAX_DEADLINE_MS)


class TelemetrySubscriber(ZmqConnection):
    """The newest telemetry records of the service at ``endpoint``.

    ``conflate`` (default) keeps only the latest record unread, for displays; without it
    every record is queued (up to ZeroMQ's high-water mark), for loggers.
    """

    def __init__(
        self, endpoint: str = DEFAULT_TELEMETRY_ENDPOINT, *, conflate: bool = True, curve: CurveClientKeys | None = None
    ) -> None:
        # CONFLATE must be set before connecting; the subscription may come after.
        super().__init__(zmq.SUB, endpoint, curve, {zmq.CONFLATE: 1} if conflate else {})
        self.socket.setsockopt(zmq.SUBSCRIBE, TOPIC)

    def receive(self, timeout_s: float = DEFAULT_TIMEOUT_S) -> dict[str, Any]:
        """The next record; :class:`ServiceUnavailable` if none arrives within ``timeout_s``."""
        if not self.socket.poll(timeout_s * 1000.0):
            raise self._unanswered("telemetry", timeout_s)
        return json.loads(self.socket.recv()[len(TOPIC) :])

