"""The dashboard's server parts without a browser: where it listens, what a page may send."""

from __future__ import annotations

import asyncio
import json
import socket

import pytest

from hexactl.adapters.cli.main import main
from hexactl.adapters.web.app import MAX_MESSAGE_BYTES, Acknowledgement, _parsed
from hexactl.adapters.web.server import DashboardError, HttpAddress, bind


@pytest.mark.parametrize("text", ["127.0.0.1:8080", "localhost:0", "[::1]:9000", "127.1.2.3:80"])
def test_loopback_addresses_are_taken(text) -> None:
    address = HttpAddress.parse(text)
    assert str(address.port) == text.rsplit(":", 1)[1]


@pytest.mark.parametrize("text", ["0.0.0.0:8080", "192.168.1.5:8080", "example.com:80", "[::]:8080"])
def test_an_address_reachable_from_the_network_is_refused_with_the_remedy(text) -> None:
    with pytest.raises(DashboardError, match="this machine only.*ssh -L"):
        HttpAddress.parse(text)


def test_the_tunnel_offered_is_to_the_port_asked_for() -> None:
    """Started again on loopback at that port, the dashboard is where the tunnel leads."""
    with pytest.raises(DashboardError, match=r"--http 127\.0\.0\.1:9000.*ssh -L 9000:127\.0\.0\.1:9000 THIS_HOST"):
        HttpAddress.parse("0.0.0.0:9000")


@pytest.mark.parametrize("text", ["8080", "127.0.0.1", "127.0.0.1:http", "127.0.0.1:70000", ":8080"])
def test_a_malformed_address_names_the_form(text) -> None:
    with pytest.raises(DashboardError, match="HOST:PORT"):
        HttpAddress.parse(text)


def test_the_command_line_refuses_a_network_address(capsys) -> None:
    assert main(["dashboard", "--http", "0.0.0.0:8080"]) == 2
    assert "listens on this machine only" in capsys.readouterr().err


def test_a_command_goes_to_the_api_unchanged_but_its_envelope() -> None:
    request_id, (cmd, fields) = _parsed(json.dumps({"type": "command", "id": 4, "cmd": "move", "pose": [1] * 6}))
    assert (request_id, cmd, fields) == (4, "move", {"pose": [1] * 6})


def test_an_ack_names_the_telemetry_message_handled() -> None:
    assert _parsed('{"type": "ack", "n": 12}') == (None, Acknowledgement(12))


@pytest.mark.parametrize(("text", "problem"), [
    ("{", "not JSON"),
    ("[1]", "a JSON object"),
    ('{"type": "hello", "id": 1}', "nothing else"),
    ('{"type": "ack"}', "an ack is"),
    ('{"type": "ack", "n": "12"}', "an ack is"),
    ('{"type": "ack", "n": true}', "an ack is"),
    ('{"type": "ack", "n": -1}', "an ack is"),
    ('{"type": "ack", "n": 1.5}', "an ack is"),
    ('{"type": "command", "id": 1, "cmd": 5}', "names its cmd"),
    ('{"type": "command", "id": 1, "cmd": "' + "x" * MAX_MESSAGE_BYTES + '"}', "at most"),
])
def test_what_is_neither_a_command_nor_an_ack_is_answered_with_the_reason(text, problem) -> None:
    _, parsed = _parsed(text)
    assert isinstance(parsed, str) and problem in parsed


def test_the_pages_connections_do_not_hold_small_messages_back() -> None:
    """The listening socket the dashboard binds itself makes connections on which asyncio
    (so uvicorn) turns Nagle's algorithm off: with it on, a reply (an E-stop's) waited for
    the page's delayed ACK of the telemetry before it, 40 ms."""
    listener = bind(HttpAddress("127.0.0.1", 0))

    async def accepted_nodelay() -> int:
        loop = asyncio.get_running_loop()
        accepted: asyncio.Future[int] = loop.create_future()

        class Probe(asyncio.Protocol):
            def connection_made(self, transport: asyncio.BaseTransport) -> None:
                connection = transport.get_extra_info("socket")
                accepted.set_result(connection.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY))
                transport.close()

        server = await loop.create_server(Probe, sock=listener)  # as uvicorn serves the socket
        try:
            with socket.create_connection(listener.getsockname()[:2]):
                return await asyncio.wait_for(accepted, 30)
        finally:
            server.close()

    assert asyncio.run(accepted_nodelay())
