"""The dashboard's server after the outside review (/tmp/rev_dash/FINDINGS.md), without a
browser:

- a command's time to live counts from when the page sent it (its ``at``, on the page's
  clock), not from when the dashboard read it: a jog or move held up in a stalled
  dashboard was carried out after the page had said "timeout" or "jog released" (1);
- ``--api`` and ``--telemetry`` of two different services: only the urgent commands are
  sent, and the pages are told (3);
- a ``deadline_ms`` or ``at`` of hundreds of digits is ``invalid_request`` (11);
- a busy port under ``serve --dashboard`` names ``--dashboard HOST:PORT`` (15);
- with CURVE keys, the dashboard needs the token it printed (5).
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import zmq
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect as connect_socket

from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.messages import Telemetry
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.security import create_keys
from hexactl.adapters.api.server import ApiServer
from hexactl.adapters.api.telemetry import TelemetryPublisher
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.web.app import PAGE_CLOCK_SAMPLES, PageClock, _serve_page
from hexactl.adapters.web.bridge import UNCOMPARED, ServiceBridge, ServiceEndpoints
from tests.api.support import LOCAL, FakeController
from tests.web.test_command_admission import HeldService, bridge_to
from tests.web.test_page_protocol import DISCONNECT, FakePage, served, text, until
from tools.browser import dashboard

WAIT_S = 30.0  # bounds a hang only
MOVE = {"pose": [0, 0, 12, 0, 0, 0], "relative": True}
JOG = {"velocity": [0, 0, 50, 0, 0, 0], "frame": "zero"}


PAGE_ORIGIN_S = time.monotonic() - 654.321
"""When the page's clock reads 0: its own origin, unrelated to this host's clock, and in the
past, as a page's is (a page's clock never reads negative; this host's monotonic clock may
be only minutes old, so an offset from it alone could)."""


def page_clock_ms() -> float:
    """A page's ``performance.now()``: ms since :data:`PAGE_ORIGIN_S`."""
    return (time.monotonic() - PAGE_ORIGIN_S) * 1000.0


def command(request_id: int, cmd: str, fields: dict[str, Any], sent_ago_ms: float | None) -> dict[str, Any]:
    """A page's command, as the WebSocket delivers it, sent ``sent_ago_ms`` before it is
    read (None: without ``at``, as an older page or a script sends it)."""
    at = {} if sent_ago_ms is None else {"at": page_clock_ms() - sent_ago_ms}
    return text({"type": "command", "id": request_id, "cmd": cmd, **fields, **at})


def ack(n: int) -> dict[str, Any]:
    return text({"type": "ack", "n": n, "at": page_clock_ms()})


# -- 1: the time to live counts from when the page sent the command ----------------------------


def test_commands_held_up_before_the_dashboard_read_them_expire_unsent_counted_from_when_the_page_sent_them() -> None:
    """The review's ws5/ws6: a move and three jogs the page sent while the dashboard was
    stopped (6 s and 2.5 s before it read them; its --timeout 5 s, the jog's deadman
    0.2 s) are answered ``expired`` and never reach the service; the jog's release is
    carried out however late (what stops motion has no time to live). Sent just now, or
    without ``at``, they are carried out; ``at`` never reaches the service."""
    service = HeldService()
    service.answers.set()
    with bridge_to(service, timeout_s=5.0) as bridge:
        page = served(FakePage(
            ack(0), ack(1),  # on time: the offset of the page's clock
            command(1, "move", MOVE, 6000.0),
            *(command(2 + renewal, "jog", JOG, 2500.0 - 50.0 * renewal) for renewal in range(3)),
            command(5, "jog", {**JOG, "velocity": [0] * 6}, 2400.0),
            command(6, "move", MOVE, 0.0),
            command(7, "move", MOVE, None),
            stays=True), bridge, replies=7)
    replies = dict(page.replies())
    assert [replies[number]["error"]["code"] for number in range(1, 5)] == ["expired"] * 4, replies
    assert "not carried out" in replies[1]["error"]["message"]
    assert all(replies[number]["ok"] for number in (5, 6, 7)), replies
    assert sorted((cmd, fields.get("velocity", [])) for cmd, fields, _ in service.sent) == [
        ("jog", [0] * 6), ("move", []), ("move", [])]  # on workers of their own: in no set order
    assert all("at" not in fields for _, fields, _ in service.sent)


def test_the_transit_is_measured_from_the_least_delayed_of_the_pages_latest_messages() -> None:
    """Whatever the offset between the clocks; a message as late as the least delayed has
    none; the window is of messages, not of time, so a stall longer than any time window
    still has the messages before it to be measured by."""
    clock = PageClock()
    origin_ms = 1e6  # the page's clock: 1000 s behind this host's
    assert clock.transit_s(0.0, origin_ms / 1000.0 + 0.003) == 0.0  # the first: taken for on time
    assert clock.transit_s(1000.0, origin_ms / 1000.0 + 1.001) == 0.0  # less delayed: now the reference
    assert clock.transit_s(2000.0, origin_ms / 1000.0 + 62.001) == pytest.approx(60.0)  # read after a 60 s stall
    for number in range(PAGE_CLOCK_SAMPLES - 1):  # the reference leaves the window only after as many messages
        clock.transit_s(70_000.0 + number, origin_ms / 1000.0 + 70.010 + number / 1000.0)
    assert clock.transit_s(80_000.0, origin_ms / 1000.0 + 80.010) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("at", ["-1", '"12"', "true", "[1]", "1e400", "9" * 400])
def test_an_at_that_is_not_a_finite_number_of_ms_is_refused_naming_it(at: str) -> None:
    """``at`` as JSON text: 1e400 is read as infinity, 400 nines as an integer no float holds."""
    service = HeldService()
    service.answers.set()
    with bridge_to(service, timeout_s=5.0) as bridge:
        page = served(FakePage(text(f'{{"type": "command", "id": 1, "cmd": "move", "pose": [0, 0, 1, 0, 0, 0], '
                                    f'"at": {at}}}'),
                               text(f'{{"type": "ack", "n": 0, "at": {at}}}'), stays=True), bridge, replies=2)
    for _, reply in page.replies():
        assert reply["error"]["code"] == "invalid_request" and reply["error"]["message"].startswith("at is"), reply
    assert service.sent == []


# -- 11: a deadline_ms of hundreds of digits -------------------------------------------------


def test_a_deadline_of_hundreds_of_digits_is_an_invalid_request_not_an_internal_error() -> None:
    """The review's ws3.py: a 401-digit deadline_ms got internal_error and a traceback."""
    service = HeldService()
    service.answers.set()
    with bridge_to(service, timeout_s=5.0) as bridge:
        page = served(FakePage(text('{"type": "command", "id": 2, "cmd": "validate_pose", "pose": [0, 0, 0, 0, 0, 0], '
                                    '"deadline_ms": 1' + "0" * 400 + "}"), stays=True), bridge, replies=1)
    ((request_id, reply),) = page.replies()
    assert request_id == 2 and reply["error"]["code"] == "invalid_request", reply
    assert "deadline_ms" in reply["error"]["message"] and service.sent == []


# -- 3: the API and the telemetry of two different services ----------------------------------


@contextmanager
def fake_service(geometry_file: Path, data_dir: Path) -> Iterator[SimpleNamespace]:
    """A fake controller behind the real API server and telemetry publisher, the records
    the command handler's (with its run), as ``hexactl serve`` publishes them."""
    context = zmq.Context()
    controller = FakeController(load_geometry(geometry_file))
    handler = CommandHandler(controller, DataDirectories([data_dir]))
    server = ApiServer(context, LOCAL, handler)
    publisher = TelemetryPublisher(context, LOCAL, handler.record, 100.0)
    server.start()
    publisher.start()
    try:
        yield SimpleNamespace(controller=controller, handler=handler, api=server.endpoint, telemetry=publisher.endpoint)
    finally:
        server.close()
        publisher.close()
        context.term()


GEOMETRY_FILE = default_config_path().resolve()  # a test may change the directory


def connect(kind: type, endpoint: str, **options: Any) -> Any:
    return kind(endpoint, **options)


def pages_view(api: str, telemetry: str, *messages: dict[str, Any]) -> FakePage:
    """A page of a dashboard on ``api`` and ``telemetry``: once the dashboard has compared
    their services (a link message says so), it sends ``messages``, each once the one
    before is answered."""
    page = FakePage(stays=True)

    async def scenario() -> None:
        bridge = ServiceBridge(ServiceEndpoints(api, telemetry, 5.0, connect=connect))
        bridge.start(asyncio.get_running_loop())
        serving = asyncio.create_task(_serve_page(bridge, page))  # type: ignore[arg-type]
        try:
            await until(lambda: bridge._run_compared is not UNCOMPARED, "the services compared")
            link = json.loads(bridge._link().text)
            await until(lambda: [message for message in page.sent if message["type"] == "link"][-1] == link,
                        "the page told")
            for number, message in enumerate(messages, start=1):
                page.incoming.put_nowait(text(message))
                await until(lambda: len(page.replies()) == number, f"reply {number}")
        finally:
            page.incoming.put_nowait(DISCONNECT)
            await asyncio.wait_for(serving, WAIT_S)
            bridge.close()

    asyncio.run(scenario())
    return page


def test_the_telemetry_and_status_name_the_services_run_as_its_events_reply(tmp_path: Path) -> None:
    with fake_service(GEOMETRY_FILE, tmp_path) as service:
        record = service.handler.record()
    assert record["run"] == service.handler.run and Telemetry.model_validate(record).run == service.handler.run


def test_with_api_and_telemetry_of_two_services_only_the_urgent_commands_are_sent_and_the_page_is_told(
        tmp_path: Path) -> None:
    """The review's t25.py: the telemetry of A, the API of B. The page is told the link is
    down, naming both endpoints; enable is refused unsent, naming them too; the E-stop goes
    to B's API as always; A is sent nothing."""
    with fake_service(GEOMETRY_FILE, tmp_path) as a, fake_service(GEOMETRY_FILE, tmp_path) as b:
        page = pages_view(b.api, a.telemetry, {"type": "command", "id": 1, "cmd": "enable"},
                          {"type": "command", "id": 2, "cmd": "estop"})
        a_calls, b_calls = list(a.controller.calls), list(b.controller.calls)
    link = [message for message in page.sent if message["type"] == "link"][-1]
    assert link["connected"] is False and "two different services" in link["message"]
    assert b.api in link["message"] and a.telemetry in link["message"] and "check --api and --telemetry" in link["message"]
    replies = dict(page.replies())
    assert replies[1]["error"]["code"] == "two_services", replies
    assert b.api in replies[1]["error"]["message"] and a.telemetry in replies[1]["error"]["message"]
    assert replies[2]["ok"], replies
    assert a_calls == [] and [name for name, _ in b_calls] == ["estop"]


def test_with_api_and_telemetry_of_one_service_commands_go_as_before(tmp_path: Path) -> None:
    with fake_service(GEOMETRY_FILE, tmp_path) as a:
        page = pages_view(a.api, a.telemetry, {"type": "command", "id": 1, "cmd": "enable"})
        calls = [name for name, _ in a.controller.calls]
    assert [message["connected"] for message in page.sent if message["type"] == "link"][-1] is True
    assert dict(page.replies())[1]["ok"] and calls == ["enable"]


# -- 15: the busy port's option ---------------------------------------------------------------


@pytest.mark.parametrize(("started_by_serve", "option"), [(True, "--dashboard HOST:PORT"), (False, "--http")])
def test_a_busy_port_names_the_option_that_chose_it(started_by_serve: bool, option: str, capsys) -> None:
    """``serve --dashboard`` (and ``demo --dashboard``) start ``hexactl dashboard`` with
    ``--exit-with``; they have no ``--http``."""
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        port = holder.getsockname()[1]
        parent = ["--exit-with", str(os.getpid())] if started_by_serve else []
        assert main(["dashboard", "--http", f"127.0.0.1:{port}", "--api", "tcp://127.0.0.1:9", "--telemetry",
                     "tcp://127.0.0.1:9", *parent]) == 2
    error = capsys.readouterr().err
    assert f"choose another port with {option}" in error and ("--http" in error) == (not started_by_serve), error


# -- 5: with CURVE keys, the dashboard needs its token ----------------------------------------


def test_with_curve_keys_the_page_its_websocket_and_downloads_need_the_token_printed(tmp_path: Path) -> None:
    """The review's nokey_raw.py: an account of this host without the keys (no Origin, no
    browser) enabled the platform through a dashboard holding the operator's key. Now its
    WebSocket is refused (403) without the token of this start, or with another; the page
    and the downloads likewise (a download link followed from the page carries it as its
    Referer)."""
    keys = create_keys(tmp_path, "op")
    with dashboard("tcp://127.0.0.1:9", "tcp://127.0.0.1:9", "--timeout", "1", "--curve-server",
                   str(keys["server_public"]), "--curve-client", str(keys["client_secret"])) as board:
        socket_url = board.url.replace("http", "ws", 1) + "ws"
        for query in ("", "?token=", "?token=guessed"):
            with pytest.raises(InvalidStatus) as refused:
                connect_socket(socket_url + query, open_timeout=WAIT_S)
            assert refused.value.response.status_code == 403
        token = re.search(r"dashboard on http://\S+/\?token=(\S+)", board.log)[1]
        with connect_socket(f"{socket_url}?token={token}", open_timeout=WAIT_S) as page:
            assert json.loads(page.recv(WAIT_S))["type"] == "hello"
        assert http_status(board.url) == 403 and http_status(f"{board.url}?token={token}") == 200
        download = f"{board.url}recordings/r.csv"
        assert http_status(download) == 403
        assert http_status(download, {"Referer": f"{board.url}?token={token}"}) == 502  # let through: no service


def test_without_curve_keys_no_token_is_printed_nor_needed(tmp_path: Path) -> None:
    with dashboard("tcp://127.0.0.1:9", "tcp://127.0.0.1:9") as board:
        assert "token=" not in board.log and http_status(board.url) == 200
        with connect_socket(board.url.replace("http", "ws", 1) + "ws", open_timeout=WAIT_S) as page:
            assert json.loads(page.recv(WAIT_S))["type"] == "hello"


def http_status(url: str, headers: dict[str, str] | None = None) -> int:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=WAIT_S) as answer:
            return answer.status
    except urllib.error.HTTPError as error:
        return error.code
