"""A dashboard on a scheme's default port is reached by the host alone: browsers leave ':80'
out of ``Host`` and ``Origin`` for http (and ':443' for https), so a dashboard on port 80 that
allowed only 'HOST:80' answered every page request 421 and refused its WebSocket. Nothing
else is loosened: another port, another host, another scheme's default stay refused.

Port 80 is not bound here (root only): the allowed set is built as ``run_dashboard`` builds
it and the checks, and the app, are called directly."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from hexactl.adapters.web.app import create_app, host_allowed, origin_allowed
from hexactl.adapters.web.bridge import ServiceBridge, ServiceEndpoints
from hexactl.adapters.web.server import allowed_hosts

ON_80 = allowed_hosts("127.0.0.1", 80)
ON_443 = allowed_hosts("localhost", 443)
ON_8080 = allowed_hosts("127.0.0.1", 8080)


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost", "[::1]", "127.0.0.1:80", "localhost:80", "[::1]:80"])
def test_on_port_80_a_host_with_or_without_its_port_is_this_dashboard(host: str) -> None:
    assert host_allowed(host, "http", ON_80) and host_allowed(host, "ws", ON_80)


@pytest.mark.parametrize("origin", ["http://127.0.0.1", "http://localhost", "http://[::1]", "http://127.0.0.1:80"])
def test_on_port_80_a_pages_origin_without_its_port_is_this_dashboards(origin: str) -> None:
    assert origin_allowed(origin, ON_80)


@pytest.mark.parametrize("origin", ["https://127.0.0.1", "https://localhost:443"])
def test_on_port_443_an_https_origin_without_its_port_is_this_dashboards(origin: str) -> None:
    assert origin_allowed(origin, ON_443)


@pytest.mark.parametrize(("host", "scheme", "allowed"), [
    ("127.0.0.1", "http", ON_8080),          # the port left out is 80, not this dashboard's 8080
    ("127.0.0.1", "https", ON_80),           # https's default is 443
    ("localhost", "http", ON_443),
    ("127.0.0.1:8080", "http", ON_80),
    ("attacker.example", "http", ON_80),
    ("attacker.example:80", "http", ON_80),
    ("127.0.0.1:", "http", ON_80),
    ("", "http", ON_80),
    ("::1", "http", ON_80),                   # an IPv6 address is named in brackets
])
def test_nothing_else_is_taken_for_this_dashboards_host(host: str, scheme: str, allowed: frozenset[str]) -> None:
    assert not host_allowed(host, scheme, allowed)


@pytest.mark.parametrize(("origin", "allowed"), [
    ("https://127.0.0.1", ON_80), ("http://127.0.0.1", ON_443), ("http://127.0.0.1", ON_8080),
    ("http://attacker.example", ON_80), ("null", ON_80), ("file://127.0.0.1", ON_80), ("ftp://127.0.0.1", ON_80),
])
def test_nothing_else_is_taken_for_this_dashboards_page(origin: str, allowed: frozenset[str]) -> None:
    assert not origin_allowed(origin, allowed)


def test_the_allowed_set_names_each_loopback_name_and_the_address_served_on_the_port() -> None:
    assert allowed_hosts("127.0.0.2", 8080) == {"127.0.0.1:8080", "localhost:8080", "[::1]:8080", "127.0.0.2:8080"}
    assert allowed_hosts("::1", 80) == {"127.0.0.1:80", "localhost:80", "[::1]:80"}


def status_for(host: str, port: int) -> int:
    """The status the dashboard's app answers ``GET /`` with ``Host: host`` on ``port``."""
    bridge = ServiceBridge(ServiceEndpoints("tcp://127.0.0.1:9", "tcp://127.0.0.1:9", 5.0, connect=None))
    app = create_app(bridge, allowed_hosts("127.0.0.1", port))
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET", "scheme": "http",
             "path": "/", "raw_path": b"/", "query_string": b"", "root_path": "", "headers": [(b"host", host.encode())],
             "server": ("127.0.0.1", port), "client": ("127.0.0.1", 5000)}
    sent: list[dict[str, Any]] = []
    requested = False

    async def receive() -> dict[str, Any]:
        nonlocal requested
        if not requested:
            requested = True
            return {"type": "http.request", "body": b"", "more_body": False}
        await asyncio.Event().wait()  # the client stays: the response decides the end
        return {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    async def served() -> None:
        await asyncio.wait_for(app(scope, receive, send), 30)

    try:
        asyncio.run(served())
    finally:
        bridge.close()
    return sent[0]["status"]


def test_a_browsers_request_to_a_dashboard_on_port_80_is_served() -> None:
    """The review's port80.py: 'Host: 127.0.0.1' on port 80 was answered 421."""
    assert status_for("127.0.0.1", 80) == 200
    assert status_for("127.0.0.1:80", 80) == 200
    assert status_for("attacker.example", 80) == 421
    assert status_for("127.0.0.1", 8080) == 421
