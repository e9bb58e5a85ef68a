"""Run the dashboard: bind the loopback address, then serve until SIGINT or SIGTERM."""

from __future__ import annotations

import ipaddress
import logging
import os
import secrets
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass

import uvicorn

from hexactl.adapters.web.app import create_app
from hexactl.adapters.web.bridge import ServiceBridge, ServiceEndpoints
from hexactl.adapters.web.connections import GuardedH11Protocol

LOOPBACK_NAMES = ("localhost",)


class DashboardError(Exception):
    """The dashboard cannot start; the message says why and what to do."""


@dataclass(frozen=True)
class HttpAddress:
    host: str
    port: int

    @classmethod
    def parse(cls, text: str) -> HttpAddress:
        """``HOST:PORT`` (port 0: any free one) on a loopback address.

        :raises DashboardError: for another form, or a host reachable from the network
        """
        host, separator, port_text = text.rpartition(":")
        host = host.strip("[]")
        if not separator or not host or not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise DashboardError(f"--http {text!r}: give HOST:PORT, e.g. 127.0.0.1:8080")
        if not _is_loopback(host):
            port = int(port_text) or 8080  # port 0 (any free one) cannot be tunnelled to in advance
            raise DashboardError(
                f"--http {text}: the dashboard drives the platform, so it listens on this machine only (127.0.0.1, ::1 "
                f"or localhost): serve it with --http 127.0.0.1:{port} and, from another machine, tunnel to it: "
                f"ssh -L {port}:127.0.0.1:{port} THIS_HOST")
        return cls(host, int(port_text))


def _is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def allowed_hosts(host: str, port: int) -> frozenset[str]:
    """The ``host:port`` forms a request's ``Host`` and a WebSocket's ``Origin`` may name
    for a dashboard listening on ``host`` (as given to ``--http``) at ``port``: the loopback
    names and ``host``, an IPv6 address in brackets. A browser leaves a scheme's default
    port out of both (port 80: ``Host: 127.0.0.1``); the app's check reads such a host as on
    that port (:func:`~hexactl.adapters.web.app.host_allowed`)."""
    named = f"[{host}]" if ":" in host else host
    return frozenset(f"{name}:{port}" for name in ("127.0.0.1", "localhost", "[::1]", named))


def bind(address: HttpAddress, option: str = "--http") -> socket.socket:
    """A listening socket on ``address``, given by the command line's ``option`` (named in
    the error). :raises DashboardError: if it cannot be bound."""
    family = socket.AF_INET6 if ":" in address.host else socket.AF_INET
    host = "127.0.0.1" if address.host == "localhost" else address.host
    # IPPROTO_TCP named, not left 0: asyncio sets TCP_NODELAY only on a connection whose
    # socket says TCP, so with 0 Nagle's algorithm held each small reply (an E-stop's)
    # behind the page's unacknowledged telemetry until its delayed ACK, 40 ms later.
    listener = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listener.bind((host, address.port))
    except OSError as error:
        listener.close()
        raise DashboardError(f"cannot listen on {address.host}:{address.port}: {error.strerror}; choose another port "
                             f"with {option}") from None
    listener.listen(64)
    return listener


def run_dashboard(address: HttpAddress, endpoints: ServiceEndpoints, log_level: str = "info",
                  parent: int | None = None) -> int:
    """Serve the dashboard on ``address`` for the service at ``endpoints`` until SIGINT or
    SIGTERM, or until process ``parent`` (the service that started it, with its option
    ``--dashboard``) is gone; prints its URL first (``dashboard on http://HOST:PORT/``).
    Reaching the service with CURVE keys, it needs a secret token of this start, in the
    URL printed (``http://HOST:PORT/?token=…``): it must add no privilege to the accounts
    of this host without the keys. Exit status 0.

    :raises DashboardError: if the address cannot be bound
    """
    listener = bind(address, "--http" if parent is None else "--dashboard HOST:PORT")
    port = listener.getsockname()[1]
    token = secrets.token_urlsafe(TOKEN_BYTES) if endpoints.curve else None
    app = create_app(ServiceBridge(endpoints), allowed_hosts(address.host, port), token)
    host = f"[{address.host}]" if ":" in address.host else address.host
    query = "" if token is None else f"?token={token}"
    print(f"dashboard on http://{host}:{port}/{query} (service API {endpoints.api}, telemetry {endpoints.telemetry})",
          flush=True)
    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
    if parent is not None:
        threading.Thread(target=_end_with, args=(parent,), name="dashboard-parent", daemon=True).start()
    # No permessage-deflate (browsers offer it): its compressor is per connection, so each
    # telemetry record would be compressed once per page, not sent as the one text every
    # page shares; on this loopback-only server it saves nothing worth that CPU.
    config = uvicorn.Config(app, http=GuardedH11Protocol, log_level=log_level, access_log=False, ws_max_size=1 << 20,
                            lifespan="on", ws_per_message_deflate=False)
    uvicorn.Server(config).run(sockets=[listener])
    return 0


TOKEN_BYTES = 32
"""The token's randomness, bytes (256 bits)."""

PARENT_POLL_S = 1.0


def _end_with(parent: int) -> None:
    """SIGTERM to this process (uvicorn's clean stop) once ``parent`` is no longer its
    parent: a service killed outright leaves no dashboard holding the port."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
