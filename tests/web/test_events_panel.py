"""The dashboard's Events panel in a real headless Chromium against a real ``hexactl
serve``: the loop's events (telemetry's ``events``) newest first, who sent the command
behind each, warnings standing out, and an event kept after the records' window of eight
has moved past it.

Another operator is an API client with a name of its own. What the page lists is checked
against the events the service reports through its API (``status``), matched by their
time on the service's clock. Every wait polls with a generous bound: nothing is judged by
how long it took.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.application.safety_log import _ROUTINE_EVENTS
from tests.reliability.support import enable
from tests.web.test_dashboard import Rig, page_on_a_service, screenshot, wait_for
from tests.web.test_validated_move import TAP, sent, tap

ANN = "ann at the bench"
DASHBOARD = "dashboard, browser "

LINES = """
return [...document.querySelectorAll('#events li')].map((li) => ({
  t: Number(li.dataset.t), code: li.dataset.code, warning: li.classList.contains('warning'),
  text: li.textContent, ago: li.querySelector('.ago').textContent,
  by: li.querySelector('.by') ? li.querySelector('.by').textContent : null,
  background: getComputedStyle(li).backgroundColor,
}));
"""
"""The panel's lines as the page shows them, top to bottom."""

AGO = re.compile(r"^(?:(?P<min>\d+) min )?(?P<s>\d+(?:\.\d)?) s ago$")
"""An age as the panel shows it: "4.2 s ago" (to 0.1 s), "37 s ago", "5 min 3 s ago" (whole seconds, down)."""


def seconds(ago: str) -> float:
    match = AGO.match(ago)
    assert match, ago
    return 60 * int(match["min"] or 0) + float(match["s"])


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("events")) as rig:
        yield rig


def lines(rig: Rig) -> list[dict]:
    return rig.page(LINES)


def script(rig: Rig, source: str, *arguments: object) -> object:
    """``source`` run in the page with ``arguments`` (``arguments[0]``, …)."""
    return rig.driver.execute_script(source, *arguments)


def service_events(rig: Rig) -> list[dict]:
    """The loop's latest events as the service reports them (oldest first)."""
    return rig.client.call("status")["status"]["events"]


def latest(rig: Rig, code: str, sender_starts: str) -> dict | None:
    """The service's newest event of ``code`` whose sender's name starts so, or None."""
    return next((event for event in reversed(service_events(rig))
                 if event["code"] == code and (event["sender"] or "").startswith(sender_starts)), None)


def line_of(rig: Rig, event: dict) -> dict | None:
    """The panel's line of ``event`` (its time and code), or None while it is not listed."""
    return next((line for line in lines(rig) if line["t"] == event["t"] and line["code"] == event["code"]), None)


def test_another_clients_enable_move_and_stop_are_listed_newest_first_naming_it(rig) -> None:
    def body() -> None:
        rig.at_rest_disabled()
        with HexactlClient(rig.served.api, timeout_s=30.0, name=ANN) as ann:
            enable(ann)  # resets an actuator its watchdog stopped while disabled (a busy host), as an operator would
            ann.call("move", pose=[0.0, 0.0, 5.0, 0.0, 0.0, 0.0], duration=0.5)
            wait_for(lambda: rig.status()["motion"] == "holding", "the move done")
            ann.call("stop")
        events = [latest(rig, code, ANN) for code in ("stop", "move", "enabled")]
        assert all(events), service_events(rig)
        shown = wait_for(lambda: all(line_of(rig, event) for event in events) and lines(rig),
                         "ann's three events on the page", seen=lambda: lines(rig))
        positions = []
        for event in events:
            line = line_of(rig, event)
            assert event["sender"].startswith(f"{ANN} ("), event  # the name it gave, and where it connected from
            assert line["by"] == f"by {event['sender']}", line
            assert event["message"] in line["text"], line
            assert not line["warning"], line
            assert AGO.match(line["ago"]), line
            positions.append(shown.index(next(s for s in shown if s["t"] == event["t"] and s["code"] == event["code"])))
        assert positions == sorted(positions), shown  # stop, move, enabled: newest first

        # the age is the service's: how long before the newest record the page has, never more
        def ages() -> tuple[float, float]:
            ago, record_t = script(
                rig, "const d = window.hexactlDashboard; const t = arguments[0];"
                "return [d.events().find((e) => e.t === t && e.code === 'enabled').ago, d.record.t];", events[2]["t"])
            return seconds(ago), record_t - events[2]["t"]

        first, bound = ages()
        assert 0.0 <= first <= bound + 0.05, (first, bound)  # shown to 0.1 s
        wait_for(lambda: ages()[0] > first, "the age counting up as telemetry arrives", seen=ages)

    rig.scenario(body)


def test_the_pages_estop_is_a_warning_naming_the_browser_and_stays_listed_after_ten_more_events(rig) -> None:
    def body() -> None:
        rig.at_rest_disabled()
        before = max((event["t"] for event in service_events(rig)), default=float("-inf"))
        rig.click("#estop")
        estop = wait_for(lambda: (event := latest(rig, "estop", DASHBOARD)) and event["t"] > before and event,
                         "the page's E-stop among the service's events", seen=lambda: service_events(rig))
        line = wait_for(lambda: line_of(rig, estop), "the E-stop on the page", seen=lambda: lines(rig))
        assert line["warning"], line
        assert line["by"] == f"by {estop['sender']}", line
        assert line["background"] not in ("rgba(0, 0, 0, 0)", "transparent"), line  # it stands out
        routine = [other for other in lines(rig) if not other["warning"]]
        assert all(other["background"] != line["background"] for other in routine), (line, routine)
        wait_for(lambda: rig.element("#state").text.strip() == "estop", "the page showing the E-stop")
        screenshot(rig.driver, "events", "#events")

        rig.client.call("reset")
        for _ in range(10):
            rig.client.call("stop")  # never refused: each one is an event
        same = "(e) => e.t === arguments[0].t && e.code === arguments[0].code && e.sender === arguments[0].sender"
        wait_for(lambda: script(rig, f"return !window.hexactlDashboard.record.events.some({same})", estop),
                 "the E-stop gone from the records' window, as the page receives them",
                 seen=lambda: rig.page("return window.hexactlDashboard.record.events"))
        kept = line_of(rig, estop)
        assert kept is not None, lines(rig)
        assert kept["warning"] and kept["by"] == f"by {estop['sender']}", kept
        listed = rig.page("return window.hexactlDashboard.events()")
        keys = [(e["t"], e["code"], e["message"], e["sender"]) for e in listed]
        assert len(keys) == len(set(keys)), listed  # each event once
        assert [e["t"] for e in listed] == sorted((e["t"] for e in listed), reverse=True), listed

    rig.scenario(body)


def test_a_senders_name_is_shown_as_text_never_as_markup(rig) -> None:
    name = '<img src=x onerror="window.hexactlInjected=1"><b>eve</b>'
    with HexactlClient(rig.served.api, timeout_s=30.0, name=name) as eve:
        eve.call("stop")
    event = wait_for(lambda: latest(rig, "stop", name), "eve's stop among the service's events",
                     seen=lambda: service_events(rig))
    line = wait_for(lambda: line_of(rig, event), "eve's stop on the page", seen=lambda: lines(rig))
    assert line["by"] == f"by {event['sender']}", line
    assert rig.page("return document.querySelectorAll('#events img, #events b').length") == 0
    assert rig.page("return window.hexactlInjected === undefined")


ROUTINE = ("enabled", "disabled", "stop", "reset", "move", "pause", "resume", "abort", "leg_locked", "leg_unlocked",
           "wave_started", "sequence_started", "sequence_finished", "sequence_aborted", "jog_started", "jog_ended",
           "jog_at_end", "stream_opened", "stream_ended", "calibration_swapped", "command_refused", "command_link_heard",
           "frames_set")
WARNINGS = ("estop", "command_link_silent", "guard_clamped", "heartbeat_lost", "actuator_fault", "actuator_state",
            "following_error", "link_failed", "send_failed", "setpoints_not_applied", "planner_error",
            "leg_lock_projection", "a_code_the_page_does_not_know")


def test_warnings_are_what_the_services_log_warns_of(rig) -> None:
    """The page's rule agrees with the service's log: INFO for its daily work, WARNING for
    the rest (a leg-lock fault among them, though its code starts as leg_locked's does)."""
    shown = script(rig, "const w = window.hexactlDashboard.eventIsWarning; return arguments[0].map((c) => [c, w(c)]);",
                   [*ROUTINE, *WARNINGS])
    assert {code for code, warning in shown if warning} == set(WARNINGS), shown
    assert all(code.startswith(_ROUTINE_EVENTS) for code in ROUTINE)
    assert not [code for code in WARNINGS if code.startswith(_ROUTINE_EVENTS)]


@pytest.fixture(scope="module")
def tapped(tmp_path_factory) -> Iterator[Rig]:
    """A page whose telemetry the test can drop (:data:`~tests.web.test_validated_move.TAP`)."""
    with page_on_a_service(tmp_path_factory.mktemp("events-tapped"), before_load=TAP) as rig:
        yield rig


@contextmanager
def ann_after_a_listed_stop(rig: Rig) -> Iterator[tuple[HexactlClient, dict]]:
    """From at rest and disabled, ``ann``'s client, and her stop once the page lists it
    (the service's event): where a burst begins."""
    rig.at_rest_disabled()
    with HexactlClient(rig.served.api, timeout_s=30.0, name=ANN) as ann:
        ann.call("stop")
        mark = latest(rig, "stop", ANN)
        wait_for(lambda: line_of(rig, mark), "the stop before the burst on the page", seen=lambda: lines(rig))
        yield ann, mark


def burst(rig: Rig, ann: HexactlClient, after: int) -> list[dict]:
    """Twenty stops by ``ann`` while the page gets no telemetry; the service's events numbered after ``after``."""
    tap(rig, drop=True)
    try:
        for _ in range(20):
            ann.call("stop")
        return ann.call("events", after=after)["events"]
    finally:
        tap(rig)


def test_a_burst_the_page_did_not_receive_is_asked_for_and_listed_whole(tapped) -> None:
    """Twenty stops while the page gets no telemetry (a record dropped on the way, as for
    a page that reads too slowly): the next record carries the burst's last eight, and the
    page asks the service for the events it skipped."""
    rig = tapped

    def body() -> None:
        with ann_after_a_listed_stop(rig) as (ann, mark):
            stopped = burst(rig, ann, mark["seq"])
        assert sum(1 for event in stopped if event["code"] == "stop") == 20, stopped
        wait_for(lambda: all(line_of(rig, event) for event in stopped), "the whole burst on the page",
                 seen=lambda: [line["code"] for line in lines(rig)][:30])
        listed = rig.page("return window.hexactlDashboard.events()")
        keys = [(e["t"], e["code"], e["message"], e["sender"]) for e in listed]
        assert len(keys) == len(set(keys)), listed  # each event once
        assert not any(e["code"] == "events_missed" for e in listed), listed

    rig.scenario(body)


def test_a_burst_while_the_page_asks_for_another_is_asked_for_next(tapped) -> None:
    """Two bursts the page did not receive, the second while its request for the first is
    unanswered: once that is answered the page asks again, for the second. Before, a gap
    that opened while the page asked was forgotten, and of the second burst the page
    listed only the eight the next record carried."""
    rig = tapped

    def body() -> None:
        with ann_after_a_listed_stop(rig) as (ann, mark):
            asked = sent(rig, "events")
            rig.page("window.hexactlTestTap.holdEventsReplies = true")
            try:
                first = burst(rig, ann, mark["seq"])
                wait_for(lambda: sent(rig, "events") > asked, "the page's request for the first burst")
                second = burst(rig, ann, first[-1]["seq"])
                wait_for(lambda: line_of(rig, second[-1]), "the record after the second burst on the page")
            finally:
                rig.page("window.hexactlTestTap.releaseReplies()")
        stops = [event for event in first + second if event["code"] == "stop"]
        assert len(stops) == 40, first + second
        wait_for(lambda: all(line_of(rig, event) for event in first + second), "both bursts whole on the page",
                 seen=lambda: [line["code"] for line in lines(rig)][:50])

    rig.scenario(body)


def failing_asks(rig: Rig, count: int) -> None:
    """The page's next ``count`` ``events`` requests answered with a failure (as a busy
    service's ``loop_silent``, or the page's own time-out)."""
    rig.page(f"window.hexactlTestTap.failEventsReplies = {count}")


def test_a_burst_whose_request_failed_is_asked_for_again_and_listed_whole(tapped) -> None:
    """The page's request for a burst fails (on a busy host its reply can come after the
    page's time-out): the page asks again with a later record. Before, the gap was
    forgotten, and of the burst the page listed only the eight the next record carried."""
    rig = tapped

    def body() -> None:
        with ann_after_a_listed_stop(rig) as (ann, mark):
            asked = sent(rig, "events")
            failing_asks(rig, 1)
            try:
                stopped = burst(rig, ann, mark["seq"])
                wait_for(lambda: all(line_of(rig, event) for event in stopped), "the whole burst on the page",
                         seen=lambda: [line["code"] for line in lines(rig)][:30])
            finally:
                failing_asks(rig, 0)
        assert sent(rig, "events") >= asked + 2  # the failed request and the one after it
        assert not any(line["code"] == "events_missed" for line in lines(rig)), lines(rig)

    rig.scenario(body)


def test_a_burst_the_page_cannot_get_is_said_to_be_missing(tapped) -> None:
    """Every request for a burst fails: after the page's last try, a warning line says
    which events it could not get and why, rather than leaving the gap unsaid."""
    rig = tapped

    def body() -> None:
        with ann_after_a_listed_stop(rig) as (ann, mark):
            failing_asks(rig, 1000)  # every request while the test runs (a busy host's page may ask for other gaps too)
            try:
                stopped = burst(rig, ann, mark["seq"])
                # Its gap begins after the newest event the page had then (merged with any earlier gap).
                gap = re.compile(r"the events after number (\d+) could not be fetched \(loop_silent, 3 times\)")
                said = wait_for(lambda: next((line for line in lines(rig) if line["code"] == "events_missed"
                                              and (found := gap.search(line["text"]))
                                              and int(found[1]) < stopped[-1]["seq"] - 8), None),
                                "the page saying the burst is missing", seen=lambda: lines(rig)[:10])
            finally:
                failing_asks(rig, 0)
        assert said["warning"], said
        assert said["text"].endswith("the service's log has them"), said

    rig.scenario(body)
