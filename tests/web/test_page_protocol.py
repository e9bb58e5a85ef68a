"""The page's WebSocket protocol without a browser: every message gets a reply, and no page
can hold up an E-stop by flooding commands (found from outside: 3000 ``abort`` messages from
one page held another page's E-stop back for 10.8 s)."""

from __future__ import annotations

import asyncio
import json
import threading
from typing import Any

from hexactl.adapters.web.app import _serve_page
from hexactl.adapters.web.bridge import ServiceBridge, ServiceEndpoints, UrgentCommand

WAIT_S = 30.0  # bounds a hang only: nothing here waits on anything but the test's own events


class FakePage:
    """A page's WebSocket: what it sends (then it goes away), and what it was sent."""

    def __init__(self, *messages: dict[str, Any]) -> None:
        self.incoming: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        for message in (*messages, {"type": "websocket.disconnect", "code": 1000}):
            self.incoming.put_nowait(message)
        self.sent: list[dict[str, Any]] = []

    async def receive(self) -> dict[str, Any]:
        return await self.incoming.get()

    async def send_text(self, text: str) -> None:
        self.sent.append(json.loads(text))

    def replies(self) -> list[tuple[Any, dict[str, Any]]]:
        return [(message["id"], message["reply"]) for message in self.sent if message["type"] == "reply"]


class EchoBridge:
    """The bridge's page-facing part: a command's reply echoes it; ``explode`` fails."""

    def subscribe(self) -> asyncio.Queue[dict[str, Any]]:
        return asyncio.Queue()

    def unsubscribe(self, queue: asyncio.Queue[dict[str, Any]]) -> None:
        pass

    async def command(self, cmd: str, fields: dict[str, Any]) -> dict[str, Any]:
        if cmd == "explode":
            raise RuntimeError("a dashboard bug")
        return {"ok": True, "cmd": cmd, "fields": fields}


def served(page: FakePage, bridge: Any) -> FakePage:
    async def scenario() -> None:
        await _serve_page(bridge, page)  # type: ignore[arg-type]
        others = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
        await asyncio.wait_for(asyncio.gather(*others, return_exceptions=True), WAIT_S)

    asyncio.run(scenario())
    return page


def text(message: dict[str, Any] | str) -> dict[str, Any]:
    return {"type": "websocket.receive", "text": message if isinstance(message, str) else json.dumps(message)}


def test_every_message_gets_a_reply_and_the_page_stays_connected() -> None:
    page = served(FakePage(
        {"type": "websocket.receive", "bytes": b"\x00\x01"},
        text('{"type": "command", "id": 1, "cmd": "move", "pose": [NaN, 0, 0, 0, 0, 0]}'),
        text('{"type": "command", "id": 2, "cmd": "move", "pose": [' + "9" * 5001 + ', 0, 0, 0, 0, 0]}'),
        text("[" * 30000 + "]" * 30000),
        text({"type": "command", "id": 3, "cmd": "explode"}),
        text({"type": "command", "id": 4, "cmd": "status", "self": 1}),
    ), EchoBridge())
    replies = page.replies()
    assert [request_id for request_id, _ in replies[:4]] == [None] * 4  # unreadable: no id to answer with
    assert all(reply["error"]["code"] == "invalid_request" for _, reply in replies[:4])
    assert "text messages" in replies[0][1]["error"]["message"]
    assert "NaN is not a JSON number" in replies[1][1]["error"]["message"]
    by_id = dict(replies[4:])
    assert by_id[3]["error"]["code"] == "internal_error" and "a dashboard bug" in by_id[3]["error"]["message"]
    assert by_id[4] == {"ok": True, "cmd": "status", "fields": {"self": 1}}


def test_an_urgent_command_takes_no_fields() -> None:
    bridge = ServiceBridge(ServiceEndpoints("tcp://127.0.0.1:9", "tcp://127.0.0.1:9", 0.1, connect=None))
    try:
        reply = asyncio.run(bridge.command("estop", {"deadline_ms": 5}))
    finally:
        bridge.close()
    assert reply["error"]["code"] == "invalid_request" and "estop takes no fields" in reply["error"]["message"]


def test_a_flood_of_one_urgent_command_costs_one_request_at_a_time_and_delays_no_other() -> None:
    release = threading.Event()
    calls: list[str] = []

    def request(cmd: str, fields: dict[str, Any]) -> dict[str, Any]:
        calls.append(cmd)
        number = len(calls)
        if cmd == "abort":
            release.wait(WAIT_S)
        return {"ok": True, "request": number}

    async def scenario() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        abort, estop = UrgentCommand("abort", request), UrgentCommand("estop", request)
        try:
            before = [asyncio.create_task(abort()) for _ in range(1000)]
            while "abort" not in calls:  # until the first abort is being sent
                await asyncio.sleep(0.001)
            during = [asyncio.create_task(abort()) for _ in range(1000)]
            stopped = await asyncio.wait_for(estop(), WAIT_S)
            assert stopped["ok"] and not release.is_set()  # through while the abort's request is still out
            release.set()
            return await asyncio.gather(*before), await asyncio.gather(*during)
        finally:
            abort.close()
            estop.close()

    before, during = asyncio.run(scenario())
    assert calls.count("abort") == 2 and calls.count("estop") == 1
    assert {reply["request"] for reply in before} == {1}
    assert {reply["request"] for reply in during} == {3}  # the presses made while one was sent: the next one
