"""The loop link between the service's loop and its API process (application/loop_link.py),
both ends in this process on real pipes: commands cross and verdicts come back, anything
that is not a command is dropped without touching the loop, and either end closing is
seen by the other."""

from __future__ import annotations

import fcntl
import multiprocessing
import os
import pickle
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TypeVar

import pytest

from hexactl.application import loop_link
from hexactl.control import commands as cmd
from hexactl.application.loop_link import REPORT_INTERVAL_S, LoopExchange, RemoteLoop, _FrameReader, _FrameWriter
from hexactl.control.config import ControllerConfig
from hexactl.control.controller import Controller
from hexactl.control.host import LoopThread
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.axes import RelativeMmRad
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.sim.ideal_actuators import IdealActuators
from tests.api.test_service import wait_for
from tests.control.conftest import SimClock

T = TypeVar("T")


@dataclass
class Link:
    """A loop in this process stepped by hand, its exchange, and a facade on the far end."""

    thread: LoopThread
    exchange: LoopExchange
    remote: RemoteLoop
    controller: Controller
    clock: SimClock
    beating: bool = False
    """Send the API's heartbeat before each exchange, as its socket thread does."""

    def cycle(self) -> None:
        """One cycle, then the exchange, as the loop thread runs them; spaced so that the
        exchange publishes every time."""
        self.thread.loop.step(self.clock.advance(self.thread.loop.period_ns))
        time.sleep(REPORT_INTERVAL_S)
        if self.beating:
            self.remote.heartbeat()
        self.exchange()

    def cycle_until_reported(self, condition) -> None:
        """Cycle until the far end's snapshot satisfies ``condition``."""

        def reported() -> bool:
            self.cycle()
            return condition(self.remote.snapshot)

        wait_for(reported, "the far end to see it")

    def cycling_meanwhile(self, call: Callable[[], T]) -> T:
        """``call()`` while another thread cycles, as the real loop runs while the API plans:
        a plan that takes over ``REPORT_SILENT_S`` (a 60 s move on a loaded host) would
        otherwise find the hand-stepped loop's last report too old and be refused ``loop_silent``."""
        done = threading.Event()

        def cycle() -> None:
            while not done.is_set():
                self.cycle()

        cycler = threading.Thread(target=cycle, name="test-cycler")
        cycler.start()
        try:
            return call()
        finally:
            done.set()
            cycler.join()


@pytest.fixture
def link(nominal: Geometry) -> Iterator[Link]:
    yield from _linked(nominal)


def _linked(nominal: Geometry, silence_s: float | None = None) -> Iterator[Link]:
    start = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, (0.0,) * 6))
    clock = SimClock()
    actuators = IdealActuators(start, clock_ns=clock)
    config = ControllerConfig()
    thread = LoopThread(actuators, ActiveGeometry.of(nominal, "nominal"), config, clock_ns=clock)
    pipes = multiprocessing.get_context("spawn")
    commands_in, commands_out = pipes.Pipe(duplex=False)
    reports_in, reports_out = pipes.Pipe(duplex=False)
    exchange = LoopExchange(thread, commands_in, reports_out, silence_s=silence_s).start()
    remote = RemoteLoop(commands_out, reports_in)
    controller = Controller(remote, config=config, nominal=nominal)
    yield Link(thread, exchange, remote, controller, clock, beating=silence_s is not None)
    remote.close()
    exchange.close()


def test_commands_cross_and_the_verdicts_come_back(link: Link) -> None:
    queued = link.controller.enable()
    assert queued.ok and queued.details["pending"]  # the loop is stepped by hand: no waiting
    ticket = queued.details["ticket"]
    link.cycle_until_reported(lambda s: any(outcome.ticket == ticket for outcome in s.outcomes))
    assert link.controller.outcome(ticket).ok and link.remote.snapshot.state.value == "enabled"

    moving = link.controller.move([0, 0, 10, 0, 0, 0], duration=0.1)  # planned on the far end
    assert moving.ok, moving.message
    ticket = moving.details["ticket"]
    link.cycle_until_reported(lambda s: any(outcome.ticket == ticket for outcome in s.outcomes))
    assert link.controller.outcome(ticket).ok, link.controller.outcome(ticket)
    link.cycle_until_reported(lambda s: s.motion.value == "holding")
    assert link.controller.telemetry().pose_command == pytest.approx((0, 0, 10, 0, 0, 0), abs=1e-6)
    assert link.exchange.rejected == 0


def test_a_verdict_is_reported_at_once_and_nothing_else_before_the_interval(
        nominal: Geometry, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(loop_link, "REPORT_INTERVAL_S", 3600.0)
    start = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, (0.0,) * 6))
    clock = SimClock()
    config = ControllerConfig()
    thread = LoopThread(IdealActuators(start, clock_ns=clock), ActiveGeometry.of(nominal, "nominal"), config, clock_ns=clock)
    pipes = multiprocessing.get_context("spawn")
    commands_in, commands_out = pipes.Pipe(duplex=False)
    reports_in, reports_out = pipes.Pipe(duplex=False)
    exchange = LoopExchange(thread, commands_in, reports_out, interval_s=3600.0).start()
    remote = RemoteLoop(commands_out, reports_in)
    try:
        first = remote.snapshot.cycle
        for _ in range(5):  # an hour between reports: these cycles are not reported
            thread.loop.step(clock.advance(thread.loop.period_ns))
            exchange()
        time.sleep(0.2)
        assert remote.snapshot.cycle == first
        ticket = Controller(remote, config=config, nominal=nominal).enable().details["ticket"]

        def judged() -> bool:  # the command crosses, the next cycle gives its verdict
            exchange()
            thread.loop.step(clock.advance(thread.loop.period_ns))
            return any(outcome.ticket == ticket for outcome in thread.snapshot.outcomes)

        wait_for(judged, "the loop's verdict")
        exchange()
        wait_for(lambda: any(outcome.ticket == ticket for outcome in remote.snapshot.outcomes), "the verdict")
        assert remote.snapshot.cycle > first
    finally:
        remote.close()
        exchange.close()


def test_anything_but_a_command_is_dropped_and_counted(link: Link) -> None:
    sender = link.remote._commands  # the API's end, written as a broken API process would
    for message in (b"not a pickle", pickle.dumps("enable"), pickle.dumps({"cmd": "enable"})):
        sender.send_bytes(message)
    cycles = link.thread.snapshot.cycle
    link.cycle()
    assert link.exchange.rejected == 3
    assert link.thread.snapshot.cycle == cycles + 1 and link.thread.snapshot.state.value == "disabled"
    assert link.thread.core.inbox == type(link.thread.core.inbox)()  # nothing queued for the loop


def test_the_api_side_sees_the_loop_end(link: Link) -> None:
    link.exchange.close()
    wait_for(lambda: link.controller.status().details["loop_failure"] is not None, "the loop's end seen")
    assert not link.controller.status().details["loop_running"]
    refused = link.controller.enable()
    assert refused.error == "loop_failed", refused


def test_the_loop_side_sees_the_api_end(link: Link) -> None:
    link.remote.close()
    link.cycle()  # no exception into the loop
    assert not link.exchange.commands_open
    link.cycle()


def test_frames_arrive_whole_whatever_the_pipe_does() -> None:
    """The non-blocking pipe ends: a frame cut by the pipe is finished later, never read
    half; a frame bigger than the pipe goes through in pieces; frames offered meanwhile
    wait their turn instead of waiting for room; the writer's close is seen."""
    pipes = multiprocessing.get_context("spawn")
    reading, writing = pipes.Pipe(duplex=False)
    reader, writer = _FrameReader(reading.fileno()), _FrameWriter(writing.fileno())
    big = bytes(range(256)) * 2048  # 512 KiB: larger than a pipe's buffer
    assert writer.offer(b"first") and writer.offer(big) is True
    assert writer.offer(b"behind") is True and writer.flush() is False  # the big one is not all written yet
    received: list[bytes] = []
    while len(received) < 3:
        received += reader.frames(8)
        writer.flush()
    assert received == [b"first", big, b"behind"]
    assert writer.offer(b"third") and reader.frames(8) == [b"third"]
    assert reader.frames(8) == [] and not reader.closed
    writing.close()
    assert reader.frames(8) == [] and reader.closed
    reading.close()
    assert writer.offer(b"to nobody") is False and writer.closed


def test_a_frame_header_no_writer_of_ours_sends_closes_the_stream(link: Link) -> None:
    """A negative length (how multiprocessing announces a frame of 2 GiB or more, never
    ours) would otherwise wait forever for its frame: the loop's end says the stream is
    unreadable and closed, which ``hexactl serve`` treats as the API process gone."""
    os.write(link.remote._commands.fileno(), struct.pack("!i", -1) + pickle.dumps("enable"))
    link.cycle()
    assert not link.exchange.commands_open
    assert link.exchange.corrupt == "a frame header of length -1"
    assert link.thread.snapshot.state.value == "disabled"  # the loop cycles on
    link.cycle()


SILENCE_S = 0.5


def _events(snapshot, code: str) -> list[str]:
    return [event.message for event in snapshot.events if event.code == code]


def test_a_silent_api_has_the_loop_brake_and_heartbeats_keep_it_going(nominal: Geometry) -> None:
    """Heartbeats (or commands) at any spacing under ``silence_s`` leave a motion alone;
    nothing for longer has the loop brake it and say so, and the next heartbeat is news
    too. Once the service stops the API on purpose, silence is nothing."""
    link = next(links := _linked(nominal, SILENCE_S))
    try:
        ticket = link.controller.enable().details["ticket"]
        link.cycle_until_reported(lambda s: any(outcome.ticket == ticket for outcome in s.outcomes))
        moving = link.cycling_meanwhile(lambda: link.controller.move([0, 0, 50, 0, 0, 0], duration=60.0))
        assert moving.ok, moving
        ticket = moving.details["ticket"]
        link.cycle_until_reported(lambda s: any(outcome.ticket == ticket for outcome in s.outcomes))
        assert link.remote.snapshot.motion.value == "moving"

        link.beating = False  # the socket thread wakes seldom, then not at all
        for _ in range(3):
            time.sleep(0.6 * SILENCE_S)
            link.remote.heartbeat()
            link.cycle()
        assert link.remote.snapshot.motion.value == "moving" and not _events(link.remote.snapshot, "command_link_silent")

        time.sleep(1.5 * SILENCE_S)
        assert link.exchange.silent_s > SILENCE_S and not link.exchange.silent  # the loop's end has not looked yet
        link.cycle_until_reported(lambda s: s.motion.value != "moving")
        assert link.exchange.silent
        [message] = _events(link.remote.snapshot, "command_link_silent")
        assert "braked to rest" in message
        assert link.remote.snapshot.state.value == "enabled"

        link.beating = True
        link.cycle_until_reported(lambda s: _events(s, "command_link_heard"))
        [heard] = _events(link.remote.snapshot, "command_link_heard")
        assert float(heard.split("after ")[1].split(" s")[0]) > SILENCE_S  # the silence it ended
        assert not link.exchange.silent

        link.exchange.expect_silence()
        link.beating = False
        time.sleep(1.5 * SILENCE_S)
        link.cycle()
        link.cycle()
        assert link.exchange.silent_s == 0.0 and len(_events(link.thread.snapshot, "command_link_silent")) == 1
    finally:
        next(links, None)


def test_no_send_waits_for_a_loop_that_does_not_read(link: Link) -> None:
    """The API's socket thread answers ``estop`` and ``status``: were a command or a
    heartbeat to wait for room in the pipe of a loop that has stopped reading (its process
    stopped or hung), every request after it would go unanswered (they did: after about
    200 moves to a SIGSTOPped loop, until the API's watchdog ended the service). Nothing is
    read here until the end: the pipe fills; then every command arrives whole, in order."""
    fcntl.fcntl(link.remote._commands.fileno(), fcntl.F_SETPIPE_SZ, 4096)  # the least: fills sooner
    stops = [cmd.Stop(ticket) for ticket in range(1_000_000, 1_000_200)]  # about 13 KiB

    def send() -> None:
        for stop in stops:
            link.remote.submit(stop)
        time.sleep(loop_link.HEARTBEAT_INTERVAL_S)
        link.remote.heartbeat()
        sent.append(link.controller.estop())

    sent: list = []
    sending = threading.Thread(target=send, daemon=True)
    sending.start()
    sending.join(10.0)  # only a bound on a hang
    assert not sending.is_alive(), "a send waits for room in the pipe"
    [estop] = sent
    assert estop.ok and estop.details["pending"]  # queued behind the stops: the loop is stepped by hand
    judged: dict[int, None] = {}  # tickets in the order of the loop's verdicts (8 commands an exchange at most)

    def estop_judged(_) -> bool:
        judged.update(dict.fromkeys(outcome.ticket for outcome in link.thread.snapshot.outcomes))
        return estop.details["ticket"] in judged

    link.cycle_until_reported(estop_judged)
    assert list(judged) == [stop.ticket for stop in stops] + [estop.details["ticket"]]
    assert link.thread.snapshot.state.value == "estop" and link.exchange.rejected == 0


def test_a_stream_target_is_dropped_rather_than_kept_waiting(link: Link) -> None:
    """A stream's targets come at up to 1 kHz, each replacing the one before: kept waiting
    for a loop that does not read, they would pile up in the API process (and reach the
    loop, when it reads again, long stale). One the pipe cannot take at once is dropped."""
    fcntl.fcntl(link.remote._commands.fileno(), fcntl.F_SETPIPE_SZ, 4096)
    zero = RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def target(sequence: int) -> cmd.StreamTarget:
        return cmd.StreamTarget(0, 1, zero, tuple(zero), tuple(zero), 0.01, sequence, time.monotonic_ns())

    taken: list[cmd.Command] = []  # what the loop's end hands the loop
    hand_over = link.thread.submit
    link.thread.submit = lambda command: (taken.append(command), hand_over(command))  # type: ignore[method-assign]
    link.remote.submit(cmd.Stop(1, sender="x" * 8192))  # more than the pipe takes: the rest waits
    link.remote.submit(target(1))
    link.remote.submit(cmd.Stop(2))  # queued behind the first: a command that is not replaced is kept
    link.cycle_until_reported(lambda _: any(outcome.ticket == 2 for outcome in link.thread.snapshot.outcomes))
    link.remote.submit(target(2))  # room now
    link.exchange()
    assert [(type(c).__name__, c.ticket, getattr(c, "sequence", None)) for c in taken] == [
        ("Stop", 1, None), ("Stop", 2, None), ("StreamTarget", 0, 2)]


def test_a_stopped_loop_finds_its_estop_behind_no_more_than_an_exchange_of_stream_targets(link: Link) -> None:
    """A stream sends a target every cycle. To a loop that had stopped reading, the pipe
    (64 KiB) filled with about 250 of them before any was dropped, and an E-stop sent then
    waited behind them all: once the loop ran again, 32 exchanges, 64 ms at 500 Hz, during
    which it followed the stale targets (seen: 70 to 160 ms after a SIGCONT). A target is
    now dropped while an exchange's worth waits unread, so the E-stop is in the next."""
    zero = RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    taken: list[cmd.Command] = []
    hand_over = link.thread.submit
    link.thread.submit = lambda command: (taken.append(command), hand_over(command))  # type: ignore[method-assign]
    for sequence in range(1000):
        link.remote.submit(cmd.StreamTarget(0, 1, zero, tuple(zero), tuple(zero), 0.01, sequence, time.monotonic_ns(),
                                            sender="hexactl cue root@vm (127.0.0.1)"))
    estop = link.controller.estop()
    link.cycle_until_reported(lambda _: any(o.ticket == estop.details["ticket"] for o in link.thread.snapshot.outcomes))
    ahead = [c for c in taken if isinstance(c, cmd.StreamTarget)]
    assert 0 < len(ahead) < loop_link.MAX_COMMANDS_PER_EXCHANGE, len(ahead)
    assert [c.sequence for c in ahead] == list(range(len(ahead)))


def test_a_report_says_how_long_ago_the_loop_sent_it(link: Link) -> None:
    """A loop whose process is stopped or hung sends no report, and the API's status and
    telemetry answered from its last as if current: now each says how long ago it came
    (``loop.report_age_s``), and a report that comes makes it fresh again."""
    link.cycle()
    silent = lambda: link.remote.report(0.25).stats.report_age_s > 0.5  # noqa: E731 - nothing sent meanwhile
    wait_for(silent, "the last report to grow old")
    last = link.remote.snapshot.cycle
    assert link.controller.telemetry().loop.report_age_s > 0.5  # what status and telemetry carry
    since = time.monotonic()
    link.cycle_until_reported(lambda s: s.cycle > last)
    # The report read now arrived after `since`: its age is bounded by the time since then,
    # however long this host held the test up (a fixed bound would measure the host).
    assert link.remote.report(0.25).stats.report_age_s <= time.monotonic() - since


def test_a_stream_target_dropped_on_the_way_is_said_to_be(link: Link) -> None:
    """Targets to a loop that does not read are dropped once a few wait unread in the pipe;
    the stream's receiver counted them ``forwarded`` all the same. Now the facade says which
    were dropped on the way, and the next target's way runs from the last the loop got."""
    enabled = link.controller.enable()
    link.cycle_until_reported(lambda s: any(o.ticket == enabled.details["ticket"] for o in s.outcomes))
    opened = link.controller.stream_open("test", timeout_s=10.0)
    assert opened.ok, opened.message
    link.cycle_until_reported(lambda s: s.stream is not None)
    results = [link.controller.stream_target([0.01 * n, 0, 0, 0, 0, 0], n, 1.0 + 0.002 * n, time.monotonic_ns())
               for n in range(1, 41)]  # the loop reads none of them meanwhile
    dropped = [n for n, result in enumerate(results, 1) if result.dropped]
    assert all(result.sent for result in results) and dropped and dropped == list(range(dropped[0], 41)), dropped
    assert link.controller._streams._open.last[0] == pytest.approx(results[dropped[0] - 2].goal[0])
