"""The page's WebSocket protocol without a browser: every message gets a reply, and no page
can hold up an E-stop by flooding commands (found from outside: 3000 ``abort`` messages from
one page held another page's E-stop back for 10.8 s), nor by not reading; telemetry is
serialised once for every page (found from outside: 400 idle pages held a new page's E-stop
back 0.6–0.9 s)."""

from __future__ import annotations

import asyncio
import json
import queue
import threading
import time
from typing import Any

from starlette.datastructures import Address
from starlette.websockets import WebSocketDisconnect, WebSocketState

from hexactl.adapters.api.client import ServiceUnavailable, TelemetrySubscriber
from hexactl.adapters.web.app import MAX_READ_AHEAD, _serve_page
from hexactl.adapters.web.bridge import (FAN_OUT_CHUNK, MAX_JOG_DEADMAN_S, OUTBOX_KINDS, TELEMETRY_WINDOW, Outbox,
                                         ServiceBridge, ServiceEndpoints, UrgentCommand, Update)

WAIT_S = 30.0  # bounds a hang only: nothing here waits on anything but the test's own events


DISCONNECT = {"type": "websocket.disconnect", "code": 1000}


class FakePage:
    """A page's WebSocket: what it sends (then it goes away, unless ``stays``), and what it
    was sent (parsed, and as the very text). It acknowledges each telemetry message as it
    is sent it, unless ``acknowledges`` is False."""

    def __init__(self, *messages: dict[str, Any], stays: bool = False, acknowledges: bool = True) -> None:
        self.incoming: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        for message in messages if stays else (*messages, DISCONNECT):
            self.incoming.put_nowait(message)
        self.sent: list[dict[str, Any]] = []
        self.texts: list[str] = []
        self.client = Address("10.0.0.9", 51000)  # where the browser connected from
        self.application_state = WebSocketState.CONNECTED
        self.gone = False
        self.acknowledges = acknowledges

    async def receive(self) -> dict[str, Any]:
        message = await self.incoming.get()
        self.gone = message is DISCONNECT
        return message

    async def send_text(self, text: str) -> None:
        if self.gone:  # as Starlette's WebSocket on uvicorn's closed connection
            self.application_state = WebSocketState.DISCONNECTED
            raise WebSocketDisconnect(1006)
        self.texts.append(text)
        self.sent.append(message := json.loads(text))
        if message["type"] == "telemetry" and self.acknowledges:
            self.acknowledge(message["n"])

    def acknowledge(self, n: int) -> None:
        self.incoming.put_nowait(text({"type": "ack", "n": n}))

    def telemetry(self) -> dict[Any, str]:
        """The telemetry texts it was sent, by their record's ``t``."""
        return {message["record"]["t"]: text for message, text in zip(self.sent, self.texts)
                if message["type"] == "telemetry"}

    def replies(self) -> list[tuple[Any, dict[str, Any]]]:
        return [(message["id"], message["reply"]) for message in self.sent if message["type"] == "reply"]


class EchoBridge:
    """The bridge's page-facing part: a command's reply echoes it; ``explode`` fails."""

    def subscribe(self) -> Outbox:
        return Outbox()

    def unsubscribe(self, outbox: Outbox) -> None:
        pass

    async def command(self, cmd: str, fields: dict[str, Any], browser: str | None = None,
                      received: float | None = None) -> dict[str, Any]:
        if cmd == "explode":
            raise RuntimeError("a dashboard bug")
        return {"ok": True, "cmd": cmd, "fields": fields, "browser": browser}


def served(page: FakePage, bridge: Any, replies: int = 0) -> FakePage:
    """``page`` served until it has ``replies`` replies and goes, and every task it started
    ended; none may end failed."""
    async def scenario() -> None:
        started: list[asyncio.Task[Any]] = []

        def kept(loop: asyncio.AbstractEventLoop, coroutine: Any, **options: Any) -> asyncio.Task[Any]:
            started.append(task := asyncio.Task(coroutine, loop=loop, **options))
            return task

        asyncio.get_running_loop().set_task_factory(kept)
        serving = asyncio.create_task(_serve_page(bridge, page))  # type: ignore[arg-type]
        await until(lambda: len(page.replies()) >= replies, f"{replies} replies")
        page.incoming.put_nowait(DISCONNECT)
        await asyncio.wait_for(serving, WAIT_S)
        ended = await asyncio.wait_for(asyncio.gather(*started, return_exceptions=True), WAIT_S)
        assert not [outcome for outcome in ended if isinstance(outcome, Exception)]  # its sender: cancelled

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
        stays=True), EchoBridge(), replies=6)
    replies = page.replies()
    assert [request_id for request_id, _ in replies[:4]] == [None] * 4  # unreadable: no id to answer with
    assert all(reply["error"]["code"] == "invalid_request" for _, reply in replies[:4])
    assert "text messages" in replies[0][1]["error"]["message"]
    assert "NaN is not a JSON number" in replies[1][1]["error"]["message"]
    by_id = dict(replies[4:])
    assert by_id[3]["error"]["code"] == "internal_error" and "a dashboard bug" in by_id[3]["error"]["message"]
    assert by_id[4] == {"ok": True, "cmd": "status", "fields": {"self": 1}, "browser": "10.0.0.9"}  # the service is told


class HungBridge(EchoBridge):
    """A service that answers nothing until ``answer`` is set; ``commands``: what it was sent."""

    def __init__(self) -> None:
        self.answer = asyncio.Event()
        self.commands: list[str] = []

    async def command(self, cmd: str, fields: dict[str, Any], browser: str | None = None,
                      received: float | None = None) -> dict[str, Any]:
        self.commands.append(cmd)
        await self.answer.wait()
        return await super().command(cmd, fields, browser)


def test_a_page_that_went_before_its_reply_had_its_command_carried_out_and_leaves_no_failed_task() -> None:
    """Found from outside: each reply to a page already gone ended its task failed, logged
    with a traceback ('Task exception was never retrieved'), 227 000 of them after a flood."""
    bridge = HungBridge()

    class Leaving(FakePage):
        async def receive(self) -> dict[str, Any]:
            message = await super().receive()
            if message is DISCONNECT:
                asyncio.get_running_loop().call_soon(bridge.answer.set)  # the replies come once it has gone
            return message

    page = served(Leaving(*(text({"type": "command", "id": n, "cmd": cmd}) for n, cmd in enumerate(("estop", "status")))),
                  bridge)
    assert sorted(bridge.commands) == ["estop", "status"] and page.replies() == []


def test_a_page_flooding_e_stops_is_read_as_they_are_answered_and_every_press_gets_its_reply() -> None:
    """Found from outside: 300 000 ``estop`` messages from one client that did not read held
    a task each; the dashboard grew past 1 GB and answered no other page for minutes."""
    presses = 10 * MAX_READ_AHEAD
    bridge = HungBridge()
    page = FakePage(*(text({"type": "command", "id": n, "cmd": "estop"}) for n in range(presses)), stays=True)

    async def scenario() -> None:
        serving = asyncio.create_task(_serve_page(bridge, page))  # type: ignore[arg-type]
        await until(lambda: len(bridge.commands) >= MAX_READ_AHEAD, "the first presses taken")
        for _ in range(100):  # turns of the loop, for a page read on regardless to take more
            await asyncio.sleep(0)
        assert len(bridge.commands) == MAX_READ_AHEAD and page.incoming.qsize() == presses - MAX_READ_AHEAD
        bridge.answer.set()
        await until(lambda: len(page.replies()) == presses, "every press answered")
        page.incoming.put_nowait(DISCONNECT)
        await asyncio.wait_for(serving, WAIT_S)

    asyncio.run(scenario())
    assert sorted(request_id for request_id, reply in page.replies() if reply["ok"]) == list(range(presses))


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
    clients: list[str] = []

    def request(cmd: str, fields: dict[str, Any], client: str) -> dict[str, Any]:
        calls.append(cmd)
        clients.append(client)
        number = len(calls)
        if cmd == "abort":
            release.wait(WAIT_S)
        return {"ok": True, "request": number}

    async def scenario() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        abort, estop = UrgentCommand("abort", request), UrgentCommand("estop", request)
        try:
            before = [asyncio.create_task(abort(f"page {n}")) for n in range(1000)]
            while "abort" not in calls:  # until the first abort is being sent
                await asyncio.sleep(0.001)
            during = [asyncio.create_task(abort(f"page {n}")) for n in range(1000, 2000)]
            stopped = await asyncio.wait_for(estop("page E"), WAIT_S)
            assert stopped["ok"] and not release.is_set()  # through while the abort's request is still out
            release.set()
            return await asyncio.gather(*before), await asyncio.gather(*during)
        finally:
            abort.close()
            estop.close()

    before, during = asyncio.run(scenario())
    assert calls.count("abort") == 2 and calls.count("estop") == 1
    assert clients == ["page 0", "page E", "page 1000"]  # each request names the press that made it wait
    assert {reply["request"] for reply in before} == {1}
    assert {reply["request"] for reply in during} == {3}  # the presses made while one was sent: the next one


def test_a_jogs_release_reaches_the_service_after_every_renewal_sent_before_it() -> None:
    arrived: list[list[float]] = []

    def request(cmd: str, fields: dict[str, Any], client: str, timeout_s: float | None = None) -> dict[str, Any]:
        if any(fields["velocity"]):
            time.sleep(0.05)  # a renewal slow to connect, as on a loaded host
        arrived.append(fields["velocity"])
        return {"ok": True, "deadman_s": MAX_JOG_DEADMAN_S}

    bridge = ServiceBridge(ServiceEndpoints("tcp://127.0.0.1:9", "tcp://127.0.0.1:9", 0.1, connect=None))
    bridge._request = request  # type: ignore[method-assign]  # the API, as the worker calls it

    async def held_then_released() -> None:
        # the service's longest deadman first: renewals slow to connect on a busy host must not
        # expire in the dashboard's queue (tests/web/test_command_admission.py tests that)
        await bridge.command("jog", {"velocity": [0, 0, 5, 0, 0, 0]})
        arrived.clear()
        renewals = [bridge.command("jog", {"velocity": [0, 0, 5, 0, 0, 0]}) for _ in range(3)]
        await asyncio.gather(*renewals, bridge.command("jog", {"velocity": [0] * 6}))

    try:
        asyncio.run(held_then_released())
    finally:
        bridge.close()
    assert arrived == [[0, 0, 5, 0, 0, 0]] * 3 + [[0] * 6]  # the release last: nothing starts the jog again


class StalledPage(FakePage):
    """A page that never reads: a send to it never completes, as uvicorn's does not while
    the socket's buffer is full."""

    def __init__(self) -> None:
        super().__init__(stays=True)
        self.stuck_sends = 0

    async def send_text(self, text: str) -> None:
        self.stuck_sends += 1
        await asyncio.Event().wait()


GEOMETRY_REPLY = {"ok": True, "calibration_id": "c1", "source": "test",
                  "geometry": {"limits": {"stroke": [0, 1], "pose_min": [0] * 6, "pose_max": [1] * 6},
                               "measurement": {"feature_points": []}}}


class FakeService:
    """The service as the bridge reaches it through ``connect``: the records the test puts
    as telemetry, a reply to every command (and the commands, in order)."""

    def __init__(self) -> None:
        self.records: queue.Queue[dict[str, Any]] = queue.Queue()
        self.commands: list[str] = []
        self.geometry_answers = threading.Event()  # cleared: the API is stuck before it answers geometry
        self.geometry_answers.set()

    def connect(self, kind: type, endpoint: str, **options: Any) -> Any:
        return self.Telemetry(self) if kind is TelemetrySubscriber else self.Client(self)

    class Telemetry:
        def __init__(self, service: FakeService) -> None:
            self.service = service

        def __enter__(self) -> FakeService.Telemetry:
            return self

        def __exit__(self, *exception: object) -> None:
            pass

        def receive(self, timeout_s: float) -> dict[str, Any]:
            try:
                return self.service.records.get(timeout=timeout_s)
            except queue.Empty:
                raise ServiceUnavailable("no record") from None

    class Client(Telemetry):
        def request(self, cmd: str, **fields: Any) -> dict[str, Any]:
            self.service.commands.append(cmd)
            if cmd == "geometry":
                self.service.geometry_answers.wait(WAIT_S)
                return GEOMETRY_REPLY
            return {"ok": True, "cmd": cmd}


class SubscribedBridge(ServiceBridge):
    """The bridge, with the outbox of each page it served kept for the test to look into."""

    def __init__(self, service: FakeService) -> None:
        super().__init__(ServiceEndpoints("api", "telemetry", WAIT_S, connect=service.connect))
        self.outboxes: list[Outbox] = []

    def subscribe(self) -> Outbox:
        self.outboxes.append(outbox := super().subscribe())
        return outbox


async def until(condition: Any, what: str) -> None:
    """Until ``condition()``, letting the loop run; a hang fails after WAIT_S (no timing asserted)."""
    async def polled() -> None:
        while not condition():
            await asyncio.sleep(0.005)

    try:
        await asyncio.wait_for(polled(), WAIT_S)
    except TimeoutError:
        raise AssertionError(f"never: {what}") from None


def test_one_text_for_every_page_and_a_page_that_does_not_read_holds_up_nothing_and_piles_up_nothing() -> None:
    service = FakeService()
    records = 300
    readers = [FakePage(stays=True) for _ in range(3)]
    stalled = StalledPage()

    async def scenario() -> None:
        bridge = SubscribedBridge(service)
        bridge.start(asyncio.get_running_loop())
        pages = [asyncio.create_task(_serve_page(bridge, page)) for page in (stalled, *readers)]  # type: ignore[arg-type]
        try:
            for t in range(records):
                service.records.put({"t": t, "calibration_id": "c1"})
            await until(lambda: all(records - 1 in page.telemetry() for page in readers), "every record's last")
            # A page that never read: its outbox holds the newest message of each kind at
            # most (one more is the send it is stuck on), not the hundreds it missed.
            assert stalled.stuck_sends == 1 and len(bridge.outboxes[0]) <= len(OUTBOX_KINDS)
            # The record is serialised once: every page is sent that very text.
            last = [page.telemetry()[records - 1] for page in readers]
            assert all(text is last[0] for text in last)
            # While the stalled page still holds its sender, another page's E-stop is answered.
            readers[0].incoming.put_nowait(text({"type": "command", "id": 7, "cmd": "estop"}))
            await until(lambda: readers[0].replies(), "the E-stop's reply")
            assert readers[0].replies() == [(7, {"ok": True, "cmd": "estop"})] and stalled.stuck_sends == 1
        finally:
            for page in (stalled, *readers):
                page.incoming.put_nowait(DISCONNECT)
            await asyncio.wait_for(asyncio.gather(*pages), WAIT_S)
            bridge.close()

    asyncio.run(scenario())
    assert service.commands.count("estop") == 1


def test_a_commands_steps_on_the_loop_do_not_wait_for_a_record_to_reach_every_page() -> None:
    """A command takes several turns of the event loop (its receipt, its task, the worker's
    answer, the reply); the fan-out of a record to hundreds of pages gives the loop back
    every :data:`FAN_OUT_CHUNK` pages, so the command is through before the record has
    reached them all, and does not wait behind a whole fan-out at each step."""
    pages = 10 * FAN_OUT_CHUNK
    handed: list[int] = []

    async def scenario() -> None:
        bridge = SubscribedBridge(FakeService())
        bridge.start(asyncio.get_running_loop())
        try:
            outboxes = [bridge.subscribe() for _ in range(pages)]  # each holds the link's state
            bridge._broadcast(Update("telemetry", '{"type": "telemetry"}', 1))

            async def command() -> None:
                for _ in range(4):
                    await asyncio.sleep(0)
                    handed.append(sum(len(outbox) == 2 for outbox in outboxes))

            await command()
            await until(lambda: all(len(outbox) == 2 for outbox in outboxes), "the record in every outbox")
        finally:
            bridge.close()

    asyncio.run(scenario())
    assert handed == sorted(handed) and 0 < handed[-1] < pages


def test_records_reach_the_pages_while_the_api_does_not_answer_the_geometry() -> None:
    """Found from outside: with telemetry flowing and the API not answering (a wrong
    ``--api``, or the API stuck), the telemetry thread waited for each geometry request's
    timeout: pages got one record every 5 s and flickered between live and NO LIVE DATA."""
    service = FakeService()
    service.geometry_answers.clear()
    page = FakePage(stays=True)

    async def scenario() -> None:
        bridge = SubscribedBridge(service)
        bridge.start(asyncio.get_running_loop())
        serving = asyncio.create_task(_serve_page(bridge, page))  # type: ignore[arg-type]
        try:
            for t in range(3):
                service.records.put({"t": t, "calibration_id": "c1"})
                await until(lambda: t in page.telemetry(), f"record {t} while the geometry is asked for")
            assert service.commands == ["geometry"]  # asked once, not once a record
            service.geometry_answers.set()
            await until(lambda: any(message["type"] == "geometry" for message in page.sent), "the geometry")
        finally:
            service.geometry_answers.set()
            page.incoming.put_nowait(DISCONNECT)
            await asyncio.wait_for(serving, WAIT_S)
            bridge.close()

    asyncio.run(scenario())


def test_a_page_is_sent_telemetry_no_further_ahead_of_it_than_the_window_and_then_the_newest() -> None:
    """Found under load: a browser starved of the CPU handled records more slowly than
    they came, and the sockets' buffers and its own queued them: its page fell further
    behind each second, 10 s after 20 s of handling 26 of the 50 a second, showing that
    old a state as live. Now a page that acknowledges nothing is sent the window's worth;
    the link's state still reaches it; and once it acknowledges, it is told so, and sent the
    newest record, not those it missed."""
    service = FakeService()
    records = 300
    page = FakePage(stays=True, acknowledges=False)

    async def scenario() -> None:
        bridge = SubscribedBridge(service)
        bridge.start(asyncio.get_running_loop())
        serving = asyncio.create_task(_serve_page(bridge, page))  # type: ignore[arg-type]
        sent = lambda: [message for message in page.sent if message["type"] == "telemetry"]  # noqa: E731
        try:
            for t in range(TELEMETRY_WINDOW):  # one at a time: a burst would reach the page as its newest only
                service.records.put({"t": t, "calibration_id": "c1"})
                await until(lambda: t in page.telemetry(), f"record {t}")
            for t in range(TELEMETRY_WINDOW, records):
                service.records.put({"t": t, "calibration_id": "c1"})
            await until(lambda: service.records.empty() and len(bridge.outboxes[0]) == 1, "a record waiting")
            assert len(sent()) == TELEMETRY_WINDOW
            bridge._set_link(False, "no telemetry: a test")  # not held back by the window
            await until(lambda: page.sent[-1]["type"] == "link" and not page.sent[-1]["connected"], "the link lost")
            acknowledged = sent()[TELEMETRY_WINDOW // 2 - 1]["n"]
            acknowledged_ms = time.time() * 1000.0
            page.acknowledge(acknowledged)  # half the window: the newest, not those missed
            await until(lambda: records - 1 in page.telemetry(), "the newest record")
            answered_ms = time.time() * 1000.0
            assert len(sent()) == TELEMETRY_WINDOW + 1 and len(bridge.outboxes[0]) == 0
            # The page is told its ack was received, behind all it was sent before the
            # ack and ahead of the record sent after: it times from its ack to this how
            # far behind it is.
            answer, newest = page.sent[-2:]
            assert newest == sent()[-1] and answer.keys() == {"type", "n", "server_ms"}
            assert answer["type"] == "acked" and answer["n"] == acknowledged
            # this host's clock when the ack was read, as telemetry's sent_ms: a page on another
            # host's clock measures how far off it is
            assert acknowledged_ms - 0.1 <= answer["server_ms"] <= answered_ms + 0.1  # sent to 0.1 ms
        finally:
            page.incoming.put_nowait(DISCONNECT)
            await asyncio.wait_for(serving, WAIT_S)
            bridge.close()

    asyncio.run(scenario())
