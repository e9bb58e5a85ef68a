"""What the service and its clients agree on, without the models: the protocol version,
the default endpoints, the telemetry topic and rate, the bound on ``deadline_ms``, how long
a client waits for an answer by default.

Standard library only: a client (``hexactl status``, ``move``, …) imports this and not
the pydantic models (:mod:`~hexactl.adapters.api.messages`), so that it starts fast.
"""

from __future__ import annotations

PROTOCOL_VERSION = 1

DEFAULT_API_ENDPOINT = "tcp://127.0.0.1:5555"
DEFAULT_TELEMETRY_ENDPOINT = "tcp://127.0.0.1:5556"
DEFAULT_TELEMETRY_RATE_HZ = 50.0
MAX_TELEMETRY_RATE_HZ = 1000.0

TOPIC = b"telemetry "
"""The prefix of every telemetry message (a single frame: ``telemetry <json>``)."""

DEFAULT_TIMEOUT_S = 5.0
"""How long a client waits for a reply or a telemetry record unless told otherwise."""

MAX_DEADLINE_MS = 3_600_000
"""The largest ``deadline_ms`` (an hour): a bound, so that a deadline is always a time."""


def check_telemetry_rate(rate_hz: float) -> float:
    """``rate_hz`` if it is a rate telemetry can be published at, records per second.

    :raises ValueError: outside (0, :data:`MAX_TELEMETRY_RATE_HZ`], naming the range
    """
    if not 0 < rate_hz <= MAX_TELEMETRY_RATE_HZ:
        raise ValueError(f"telemetry rate {rate_hz:g} Hz outside (0, {MAX_TELEMETRY_RATE_HZ:g}]: "
                         f"choose a rate in that range, e.g. {DEFAULT_TELEMETRY_RATE_HZ:g}")
    return rate_hz
