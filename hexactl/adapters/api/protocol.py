"""What the service and its clients agree on, without the models: the protocol version,
the default endpoints, how a client names itself, the telemetry topic and rate, the bound
on ``deadline_ms``, how long a client waits for an answer by default, a recording's name.

Standard library only: a client (``hexactl status``, ``move``, …) imports this and not
the pydantic models (:mod:`~hexactl.adapters.api.messages`), so that it starts fast.
"""

from __future__ import annotations

import getpass
import os
import socket
import sys
from pathlib import Path

PROTOCOL_VERSION = 1

MAX_REQUEST_BYTES = 64 * 1024
"""Largest request answered; a larger one gets ``too_large``."""

TRANSPORT_MAX_BYTES = 16 * MAX_REQUEST_BYTES
"""``zmq.MAXMSGSIZE``: ZeroMQ drops the connection of a peer sending a frame larger than
this, without a reply (nothing can be answered without reading it all); between
:data:`MAX_REQUEST_BYTES` and this the request is read, counted and refused."""

DEFAULT_API_ENDPOINT = "tcp://127.0.0.1:5555"
DEFAULT_TELEMETRY_ENDPOINT = "tcp://127.0.0.1:5556"
DEFAULT_TELEMETRY_RATE_HZ = 50.0
MAX_TELEMETRY_RATE_HZ = 1000.0

CLIENT_NAME_PROPERTY = "X-Client"
"""The ZeroMQ connection property (``ZMQ_METADATA``, set before connecting) by which a
client names itself to the service, for people: the service's events and log name who
sent each command by it and by where the connection comes from. A connection property,
not a request field, so that a named client works with a service that knows nothing of
names, and a service with any client."""

MAX_CLIENT_NAME = 64
"""The most characters of a client's name the service keeps."""

RECORDING_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$"
"""A recording's name, as ``record`` takes it (``.csv`` and ``.json`` are added): here
for the dashboard's download route too, which must not import the models."""
RECORDING_EXTENSION_PATTERN = r"\.([cC][sS][vV]|[jJ][sS][oO][nN])$"
"""What a recording's name may not end with: ``r1.json`` made ``r1.json.csv`` and
``r1.json.json``. A pattern of its own (the schema's ``not``), not a lookahead in the
name's: regular-expression engines of the RE2 family, which clients' validators use,
have none."""

MAX_RECORDING_S = 3600
"""The longest recording, s: an hour is 1.8 million rows (about 0.5 GB) at 500 Hz."""

MAX_RECORDING_DIVISOR = 10_000
"""The largest ``divisor`` of a recording (every divisor-th cycle recorded)."""


def default_client_name() -> str:
    """``PROGRAM USER@HOST`` (``hexactl alice@bench-2``): who this process is, for people;
    PROGRAM the package run with ``python -m``, else the script's file name."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None:
        program = spec.name.partition(".")[0]
    else:
        program = Path(sys.argv[0]).name if sys.argv and sys.argv[0] not in ("", "-c") else "python"
    try:
        user = getpass.getuser()
    except (KeyError, OSError):  # no name for this uid (a container)
        user = f"uid {os.getuid()}"
    return f"{program} {user}@{socket.gethostname()}"[:MAX_CLIENT_NAME]


TOPIC = b"telemetry "
"""The prefix of every telemetry message (a single frame: ``telemetry <json>``)."""

GOAL_TOLERANCE = 5e-4
"""mm or deg: two poses closer than this on every axis (what shows in 3 decimals) are the
same to an operator: a goal farther from the requested pose was projected by the service
(leg-lock), and a motion at rest farther from its goal stopped short of it (one that ran
its course rests on it to 1e-9, leg-lock moves included)."""

DEFAULT_TIMEOUT_S = 5.0
"""How long a client waits for a reply or a telemetry record unless told otherwise."""

MAX_DEADLINE_MS = 3_600_000
"""The largest ``deadline_ms`` (an hour): a bound, so that a deadline is always a time."""

MAX_TIMEOUT_S = MAX_DEADLINE_MS / 1000.0
"""The longest a client waits: beyond, no request is carried out, and the wait overflowed."""

MIN_TELEMETRY_RATE_HZ = 1.0 / DEFAULT_TIMEOUT_S
"""Slower, a client waiting its default time for a record may get none (and at 1e-300 Hz the
publisher's period overflowed, killing it)."""


def check_telemetry_rate(rate_hz: float) -> float:
    """``rate_hz`` if it is a rate telemetry can be published at, records per second.

    :raises ValueError: outside [:data:`MIN_TELEMETRY_RATE_HZ`, :data:`MAX_TELEMETRY_RATE_HZ`], naming the range
    """
    if not MIN_TELEMETRY_RATE_HZ <= rate_hz <= MAX_TELEMETRY_RATE_HZ:
        raise ValueError(f"telemetry rate {rate_hz:g} Hz outside [{MIN_TELEMETRY_RATE_HZ:g}, {MAX_TELEMETRY_RATE_HZ:g}]: "
                         f"choose a rate in that range, e.g. {DEFAULT_TELEMETRY_RATE_HZ:g}")
    return rate_hz


_LOCAL_HOSTS = frozenset({"localhost", "lo"})


def endpoints_clash(first: str, second: str) -> bool:
    """True if binding both endpoints would take one address twice: the same ``ipc://``
    path, or TCP on one port (not ``*``: a free one) of one host, of any host where either
    is a wildcard (``*``, ``0.0.0.0``, ``[::]``), or of ``localhost`` and a loopback address."""
    (scheme, _, address), (other_scheme, _, other_address) = first.partition("://"), second.partition("://")
    if scheme != other_scheme or scheme not in ("tcp", "ipc", "inproc"):
        return False
    if scheme != "tcp":
        return address == other_address
    (host, _, port), (other_host, _, other_port) = address.rpartition(":"), other_address.rpartition(":")
    if port != other_port or port in ("*", "0"):
        return False
    hosts = {host.strip("[]"), other_host.strip("[]")}
    if len(hosts) == 1 or hosts & {"*", "0.0.0.0", "::"}:
        return True
    return "localhost" in hosts and all(is_local_endpoint(f"tcp://{host}:1") for host in hosts)


def is_local_endpoint(endpoint: str) -> bool:
    """True for ``inproc://``, ``ipc://`` and TCP on a loopback address or ``localhost``."""
    scheme, _, address = endpoint.partition("://")
    if scheme in ("inproc", "ipc"):
        return True
    if scheme != "tcp":
        return False
    host = address.rsplit(":", 1)[0]
    if ";" in host:  # tcp://SOURCE;DESTINATION is a connect form: judge where it binds
        host = host.split(";", 1)[0]
    host = host.strip("[]")
    if host in _LOCAL_HOSTS:
        return True
    import ipaddress  # only for a host that is no name: not for every command's start-up

    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # "*", an interface name or a host name: may be reachable from elsewhere
        return False
