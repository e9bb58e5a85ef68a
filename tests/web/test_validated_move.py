"""The dashboard's "validate, then go" and its jog with two operators on one platform and
with stale data, in a real headless Chromium against a real ``hexactl serve`` (found from
outside, at 3 a.m.: a move validated before another operator changed the work frame or
the calibration went, at Go, where the new frame put it; Go stayed enabled with no live
data; a held jog was still renewed while only the page's telemetry was stale).

The other operator is an API client. What reaches the page is tapped in the page itself
(:data:`TAP`, installed before the page's scripts): its telemetry dropped (stale, with the
WebSocket open) or its frames held (the page not yet told of a change: the race the
service's guard closes), and the commands it sends counted. Everything is judged by the
page's state and the service's, never by how long anything took.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.support.ui import Select

from hexactl.adapters.api.client import CommandError
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.control.results import DEADMAN_LAPSED
from tests.web.test_dashboard import Rig, page_on_a_service, screenshot, wait_for

TAP = """
(() => {
  const Native = window.WebSocket;
  const tap = { dropTelemetry: false, recordFields: null, sent: [], lastTelemetryAt: null, losses: 0, late: false,
                holdEventsReplies: false, failEventsReplies: 0, eventsIds: new Set(), heldReplies: [],
                jogIds: new Set(), jogReplyFields: null, intervals: [], jogs: [], holdJogs: null, heldJogs: [] };
  const nativeSetInterval = window.setInterval.bind(window);
  window.setInterval = (callback, ms, ...rest) => { tap.intervals.push(ms); return nativeSetInterval(callback, ms, ...rest); };
  tap.releaseReplies = () => { tap.holdEventsReplies = false; tap.heldReplies.splice(0).forEach((f) => f()); };
  tap.releaseJogs = () => { tap.holdJogs = null; tap.heldJogs.splice(0).forEach((f) => f()); };
  tap.releaseRenewals = () => {  // the held renewals go on their way; a held restart stays held, and any to come
    tap.holdJogs = 'restarts';
    const held = tap.heldJogs.splice(0);
    tap.heldJogs.push(...held.filter((f) => f.command.restarts != null));
    held.filter((f) => f.command.restarts == null).forEach((f) => f());
  };
  window.hexactlTestTap = tap;
  window.WebSocket = class extends Native {
    constructor(...args) {
      super(...args);
      super.addEventListener('close', () => { tap.losses += 1; });
    }
    addEventListener(type, listener, options) {
      if (type !== 'message') return super.addEventListener(type, listener, options);
      const handle = (event) => {
        listener(event);
        const late = window.hexactlDashboard?.dataLoss === 'late';  // behind the records: lost on its own too
        if (late && !tap.late) tap.losses += 1;
        tap.late = late;
      };
      return super.addEventListener(type, (event) => {
        const message = JSON.parse(event.data);
        if (message.type === 'reply' && tap.failEventsReplies > 0 && tap.eventsIds.has(message.id)) {
          tap.failEventsReplies -= 1;
          message.reply = { ok: false, error: { code: 'loop_silent', message: 'failed by the test tap' } };
          handle(new MessageEvent('message', { data: JSON.stringify(message) }));
          return;
        }
        if (message.type === 'reply' && tap.jogReplyFields !== null && tap.jogIds.has(message.id)) {
          Object.assign(message.reply, tap.jogReplyFields);
          handle(new MessageEvent('message', { data: JSON.stringify(message) }));
          return;
        }
        if (message.type === 'reply' && tap.holdEventsReplies && tap.eventsIds.has(message.id)) {
          tap.heldReplies.push(() => handle(event));
          return;
        }
        if (message.type === 'link' && message.connected !== true) tap.losses += 1;
        if (message.type !== 'telemetry') { handle(event); return; }
        const now = performance.now();
        if (tap.dropTelemetry) {  // lost on the way, after the server's window: acknowledged, as a page would
          tap.lastTelemetryAt = null;
          super.send(JSON.stringify({ type: 'ack', n: message.n }));
          return;
        }
        if (tap.lastTelemetryAt !== null && now - tap.lastTelemetryAt > LOSS_GAP_MS) tap.losses += 1;
        tap.lastTelemetryAt = now;
        if (tap.recordFields === null) { handle(event); return; }
        Object.assign(message.record, tap.recordFields);
        handle(new MessageEvent('message', { data: JSON.stringify(message) }));
      }, options);
    }
    send(data) {
      const command = JSON.parse(data);
      if (command.type !== 'command') return super.send(data);
      tap.sent.push(command.cmd);
      if (command.cmd === 'events') tap.eventsIds.add(command.id);
      if (command.cmd === 'jog') {
        tap.jogIds.add(command.id);
        tap.jogs.push(command);
        if (tap.holdJogs === 'all' || (tap.holdJogs === 'restarts' && command.restarts != null)) {
          // a restart goes stamped when released, as one the page made then: held from its making,
          // it would expire on the way (one deadman period) and the page rightly release the button
          const send = () => super.send(command.restarts == null ? data
            : JSON.stringify({ ...command, at: performance.now() }));
          tap.heldJogs.push(Object.assign(send, { command }));
          return undefined;
        }
      }
      return super.send(data);
    }
  };
})();
""".replace("LOSS_GAP_MS", "1500")
"""Wraps the page's WebSocket: ``hexactlTestTap.dropTelemetry`` drops every telemetry
record, ``recordFields`` (not null) replaces those fields of each record (the frames held,
a field the service cannot be made to send), ``holdEventsReplies``
holds the replies to the page's ``events`` requests until ``releaseReplies()``,
``failEventsReplies`` (a count) turns that many of them into failures (``loop_silent``),
``jogReplyFields`` (not null) replaces those fields of the replies to its jogs, ``jogs`` lists
every jog command the page sends, ``holdJogs`` (``all``, or ``restarts``: only those that name a
lapsed jog) holds them on the way until ``releaseJogs()`` (a stalled page) or, for the
renewals only, ``releaseRenewals()`` (which holds restarts from then on), ``intervals``
lists the period of every ``setInterval`` the page starts, ``sent`` lists the ``cmd`` of every
command the page sends, and ``losses`` counts the times the page may
have lost its live data on its own (not by ``dropTelemetry``): the socket closed, the
service's link down, records further apart than 1.5 s (the page calls 2 s stale), or the
page further behind the records than it shows as live (``late``), as when a busy host holds
up the browser or the dashboard."""

ATTEMPTS = 3

PIVOT = [0, 0, 300, 0, 0, 0]
MOVED_WORK = [30, 0, 300, 0, 0, 0]
WORK_GOAL = [0, 0, 0, 4, 0, 0]  # a 4° roll about the pivot


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("validated-move"), before_load=TAP) as rig:
        yield rig


def tap(rig: Rig, *, drop: bool = False, hold_frames: bool = False) -> None:
    """What the page's tap does from now on (both off: the page sees everything)."""
    rig.page(f"const t = window.hexactlTestTap; t.dropTelemetry = {str(drop).lower()}; "
             f"t.recordFields = {'{frames: window.hexactlDashboard.record.frames}' if hold_frames else 'null'};")


def sent(rig: Rig, cmd: str) -> int:
    """How many ``cmd`` commands the page has sent."""
    return rig.page(f"return window.hexactlTestTap.sent.filter(c => c === '{cmd}').length")


def live(rig: Rig) -> bool:
    return rig.page("return window.hexactlDashboard.dataLoss === null")


def go_enabled(rig: Rig) -> bool:
    return rig.element("#move-go").is_enabled()


def move_result(rig: Rig) -> str:
    return rig.element("#move-result").text


def ready_in_frames(rig: Rig) -> dict:
    """The page sees everything and has live data; enabled from the page, at rest, the
    frames on a pivot 300 mm above the platform; the service's status record."""
    tap(rig)
    wait_for(lambda: live(rig), "live data on the page")
    rig.enabled_from_the_page()
    rig.client.call("set_frames", tool=PIVOT, work=PIVOT, soft_limits={})
    wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.work") == PIVOT, "the frames on the page")
    return rig.status()


def validated_in_page(rig: Rig, pose: list[float], frame: str) -> None:
    """The operator types ``pose`` in ``frame`` and validates it: valid, Go enabled."""
    for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), pose):
        rig.fill(f"#move-{axis}", value)
    Select(rig.shown("#move-frame")).select_by_value(frame)
    rig.fill("#move-duration", 1)
    rig.click("#move-validate")
    wait_for(lambda: move_result(rig) != "validating…", "the validation's answer")  # set by the click itself
    assert move_result(rig).startswith("valid: duration") and go_enabled(rig), move_result(rig)


def attempted(rig: Rig, scenario: Callable[[], None]) -> None:
    """``scenario`` (judged by :meth:`Rig.scenario`, which runs it again after a stall's
    faults), again from the start if it failed after the page lost its live data on its
    own (the tap's ``losses``): a validation is rightly withdrawn then. :data:`ATTEMPTS` in all."""
    for attempt in range(1, ATTEMPTS + 1):
        losses = rig.page("return window.hexactlTestTap.losses")
        try:
            rig.scenario(scenario)
            return
        except (AssertionError, CommandError) as error:
            if attempt == ATTEMPTS or rig.page("return window.hexactlTestTap.losses") == losses:
                raise
            print(f"attempt {attempt} failed after the page lost its live data on its own: {error!r:.300}")


def assert_not_moved(rig: Rig, before: dict) -> None:
    after = rig.status()
    assert after["motion"] == "holding" and after["goal"] is None, after
    assert after["pose_command"] == before["pose_command"], (before["pose_command"], after["pose_command"])


def test_a_work_frame_changed_by_another_operator_after_validation_disables_go_and_says_why(rig) -> None:
    def scenario() -> None:
        before = ready_in_frames(rig)
        validated_in_page(rig, WORK_GOAL, "work")
        moves = sent(rig, "move")
        rig.client.call("set_frames", work=MOVED_WORK)  # the other operator
        wait_for(lambda: not go_enabled(rig), "Go disabled", seen=lambda: move_result(rig))
        assert move_result(rig) == "the work frame changed since you validated: validate again"
        assert "ghost" not in rig.element("#view3d-hud").text  # the goal previewed is gone
        screenshot(rig.driver, "move-frames-changed", "#move-result")
        assert sent(rig, "move") == moves
        assert_not_moved(rig, before)

    attempted(rig, scenario)


def test_go_pressed_before_the_page_saw_another_operators_frame_is_refused_by_the_service(rig) -> None:
    def scenario() -> None:
        before = ready_in_frames(rig)
        validated_in_page(rig, WORK_GOAL, "work")
        tap(rig, hold_frames=True)  # the page is not told of the change yet
        rig.client.call("set_frames", work=MOVED_WORK)
        changed_at = rig.status()["t"]
        wait_for(lambda: rig.page("return window.hexactlDashboard.record.t") > changed_at,
                 "a record from after the change on the page")
        assert go_enabled(rig), move_result(rig)  # the page cannot know: the race
        rig.click("#move-go")
        wait_for(lambda: "changed_since_validation" in move_result(rig), "the service's refusal on the page",
                 seen=lambda: move_result(rig))
        assert "the work frame changed since this move was validated" in move_result(rig), move_result(rig)
        assert "validate it again" in move_result(rig), move_result(rig)
        assert sent(rig, "move") >= 1
        assert_not_moved(rig, before)
        assert not go_enabled(rig)
        tap(rig)

    attempted(rig, scenario)


def test_a_calibration_loaded_by_another_operator_after_validation_disables_go_and_says_why(rig) -> None:
    nominal = load_geometry(default_config_path())
    calibrated = nominal.model_copy(update={"name": "other operator's", "zero_lengths": tuple(
        length + 0.3 for length in nominal.zero_lengths)})

    def scenario() -> None:
        ready_in_frames(rig)
        validated_in_page(rig, WORK_GOAL, "work")
        moves = sent(rig, "move")
        try:
            rig.client.call("load_calibration", toml=geometry_to_toml(calibrated))
            wait_for(lambda: not go_enabled(rig), "Go disabled", seen=lambda: move_result(rig))
            assert move_result(rig) == "the calibration changed since you validated: validate again"
            assert sent(rig, "move") == moves
        finally:
            if rig.status()["calibration_id"] == geometry_id(calibrated):
                rig.client.call("rollback_calibration")
        wait_for(lambda: rig.status()["calibration_id"] == geometry_id(nominal), "rolled back")

    attempted(rig, scenario)


def test_go_is_disabled_while_the_page_has_no_live_data_with_its_socket_open(rig) -> None:
    def scenario() -> None:
        before = ready_in_frames(rig)
        validated_in_page(rig, WORK_GOAL, "work")
        moves = sent(rig, "move")
        tap(rig, drop=True)
        wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss") == "telemetry", "the page's data stale")
        assert not go_enabled(rig)
        assert move_result(rig).startswith("no live data (no telemetry has reached the page)"), move_result(rig)
        assert "validate again once live data return" in move_result(rig), move_result(rig)
        tap(rig)
        wait_for(lambda: live(rig), "live data again")
        assert not go_enabled(rig)  # withdrawn, not suspended: validate again
        assert sent(rig, "move") == moves
        assert_not_moved(rig, before)

    attempted(rig, scenario)


@contextmanager
def _held_x_jog(rig) -> Iterator[Any]:
    """The +x jog button held down (5 mm/s), once the platform moves; released on the way out."""
    ready_in_frames(rig)
    rig.fill("#jog-speed", 5)
    start_x = rig.status()["pose_command"][0]
    button = rig.shown('.jog[data-axis="x"][data-direction="1"]')
    try:
        rig.jog_held(button, lambda: rig.status()["pose_command"][0] > start_x + 1.0, "the platform jogging while held")
        yield button
    finally:
        ActionChains(rig.driver).release(button).perform()


def test_a_held_jog_stops_being_renewed_when_only_the_pages_telemetry_is_stale(rig) -> None:
    def scenario() -> None:
        try:
            with _held_x_jog(rig) as button:
                tap(rig, drop=True)
                wait_for(lambda: rig.element("#jog-status").text.startswith("jog released: no live data"),
                         "the page saying why the jog stopped", seen=lambda: rig.element("#jog-status").text)
                assert "held" not in button.get_attribute("class").split()
                renewals = sent(rig, "jog")
                # the page releases the jog it drops (a zero velocity), not waiting for the deadman
                record = wait_for(lambda: (r := rig.status())["motion"] == "holding" and r["last_jog"] and r,
                                  "the page's release braking the jog", seen=rig.status)
                assert record["last_jog"]["reason"] == "released", record["last_jog"]
                assert sent(rig, "jog") == renewals  # none since: the button is still held
        finally:
            tap(rig)

    attempted(rig, scenario)


def test_a_held_jog_is_renewed_as_often_as_the_services_deadman_asks(rig) -> None:
    """Renewed four times a deadman, as ``hexactl jog`` renews, the deadman being what the
    service's reply says (the page renewed every 100 ms whatever it said: two renewals a
    0.2 s deadman, one late renewal from a brake). Here the tap makes the replies say 0.6 s."""
    deadman_s = 0.6

    def scenario() -> None:
        ready_in_frames(rig)
        rig.fill("#jog-speed", 5)
        start_x = rig.status()["pose_command"][0]
        rig.page(f"const t = window.hexactlTestTap; t.jogReplyFields = {{deadman_s: {deadman_s}}}; t.intervals = [];")
        button = rig.shown('.jog[data-axis="x"][data-direction="1"]')
        try:
            rig.jog_held(button, lambda: rig.status()["pose_command"][0] > start_x + 1.0, "the platform jogging while held")
            wait_for(lambda: deadman_s * 1000 / 4 in rig.page("return window.hexactlTestTap.intervals"),
                     "the page renewing every quarter of the deadman its reply stated",
                     seen=lambda: rig.page("return window.hexactlTestTap.intervals"))
            renewals = sent(rig, "jog")
            wait_for(lambda: sent(rig, "jog") >= renewals + 3, "the page renewing the held jog",
                     seen=lambda: rig.page("return [document.getElementById('jog-status').textContent, "
                                           "window.hexactlDashboard.dataLoss]"))
        finally:
            ActionChains(rig.driver).release(button).perform()
            rig.page("window.hexactlTestTap.jogReplyFields = null;")
        wait_for(lambda: rig.status()["motion"] == "holding", "the jog braked to rest after the release")

    attempted(rig, scenario)


def test_another_clients_stop_ends_a_held_jog_for_good(rig) -> None:
    """Found from outside (with hexactl jog, which the page renews as): a stop from another
    client braked the held jog, and the next renewal started a new one. The renewals name
    their jog: once stopped, the page stops renewing and says why; the platform stays at rest
    while the button is still held."""

    def scenario() -> None:
        with _held_x_jog(rig) as button:
            rig.client.call("stop")
            wait_for(lambda: "has ended (stopped)" in rig.element("#jog-status").text,
                     "the page saying the jog was stopped", seen=lambda: rig.element("#jog-status").text)
            assert "held" not in button.get_attribute("class").split()
            at_rest = wait_for(lambda: (r := rig.status())["motion"] == "holding" and r, "the platform at rest",
                               seen=rig.status)
            renewals = sent(rig, "jog")
            assert at_rest["jog"] is None and at_rest["last_jog"]["reason"] == "stopped"
            rig.client.call("status")  # a round trip: any renewal the page still sent has reached the service
            assert rig.status()["jog"] is None and rig.status()["motion"] == "holding"
            assert sent(rig, "jog") == renewals  # none since: the button is still held

    attempted(rig, scenario)


def test_soft_limits_left_empty_keep_what_is_in_force_not_what_the_page_last_heard(rig) -> None:
    """The page used to fill an empty soft-limit input from its latest record and send the
    soft limits whole: a bound another client had set since, which the page had not yet
    shown, was removed. It now sends only what is filled in, and the service keeps the rest."""
    rig.client.call("clear_frames")
    wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.soft_limits.lower[0]") is None,
             "the page told of no soft limits")
    lower = [round(rig.status()["pose_command"][0]) - 50, None, None, None, None, None]  # the platform inside it
    try:
        tap(rig, hold_frames=True)  # the page's records keep saying: no soft limits
        rig.client.call("set_frames", soft_limits={"lower": lower})  # another client, unseen by the page
        for selector in ("#frame-work", "#frame-tool", "#soft-lower", "#soft-upper"):
            rig.fill(selector, "")
        rig.fill("#soft-max-tilt", "12")
        rig.click("#frames-apply")
        expected = {"lower": lower, "upper": [None] * 6, "max_tilt_deg": 12}
        soft = lambda: rig.client.call("frames")["frames"]["soft_limits"]  # noqa: E731
        wait_for(lambda: soft() == expected, f"the service's soft limits {expected}",
                 seen=lambda: (soft(), rig.element("#frames-result").text))
        assert "soft limits: lower" in rig.element("#frames-result").text  # the reply's, not the page's record
    finally:
        tap(rig)
        rig.client.call("clear_frames")



def _stalled_until_lapsed(rig) -> int:
    """The page's jog renewals held on the way (a stalled page) until the service's deadman
    lapses and the platform brakes to rest; the jog's number."""
    rig.page("window.hexactlTestTap.holdJogs = 'all';")

    def lapsed() -> int | None:  # the jog the page renews (a busy host may have lapsed one before: it restarted)
        # the last held: a renewal, or a restart when a renewal sent before the hold was refused as lapsed
        record, held = rig.status(), rig.page("const last = window.hexactlTestTap.heldJogs.at(-1)?.command; "
                                              "return last && (last.renews ?? last.restarts)")
        last = record["last_jog"]
        return (last["jog"] if held and record["jog"] is None and last == {"jog": held, "reason": DEADMAN_LAPSED}
                else None)

    return wait_for(lapsed, "the deadman lapsed", seen=rig.status)


def _jogs_sent(rig) -> list[dict]:
    return rig.page("return window.hexactlTestTap.jogs")


def test_a_held_jog_whose_renewals_came_late_starts_again_in_place_of_the_lapsed_one(rig) -> None:
    """A stall of the page lets the deadman lapse: the button still held, the page starts a
    new jog naming the lapsed one (``restarts``), and the platform jogs on."""

    def scenario() -> None:
        pressed = len(_jogs_sent(rig))  # the jog that starts the hold: the tap lists every jog since the page loaded
        try:
            with _held_x_jog(rig):
                lapsed = _stalled_until_lapsed(rig)
                x = rig.status()["pose_command"][0]
                rig.page("window.hexactlTestTap.releaseJogs();")
                wait_for(lambda: rig.status()["pose_command"][0] > x + 1.0, "the platform jogging again",
                         seen=lambda: rig.element("#jog-status").text)
                jogs = _jogs_sent(rig)[pressed:]
                assert any(jog.get("restarts") == lapsed for jog in jogs), jogs
                # every jog after the press names one: none could start unconditionally over a stop
                assert all("renews" in jog or "restarts" in jog for jog in jogs[1:]), jogs
                jogging = rig.status()["jog"]  # none when the new jog lapsed too on a busy host, after moving
                assert jogging is None or jogging["jog"] != lapsed, jogging
        finally:
            rig.page("window.hexactlTestTap.releaseJogs();")
        wait_for(lambda: rig.status()["motion"] == "holding", "the jog braked to rest after the release")

    attempted(rig, scenario)


def test_a_stop_between_the_lapse_and_the_pages_restart_ends_the_held_jog_for_good(rig) -> None:
    """Found in the full suite on a busy host: the page's renewals came late, the jog
    lapsed, the page was told so and started a new jog, which reached the service after
    another client's stop and ran on. The restart names the lapsed jog; the stop came after
    the lapse, so the restart is refused, the page stops renewing and says why, and the
    platform stays at rest while the button is still held."""

    def scenario() -> None:
        pressed = len(_jogs_sent(rig))  # as above
        try:
            with _held_x_jog(rig) as button:
                lapsed = _stalled_until_lapsed(rig)
                # the renewals go on to be refused as lapsed; the page's restart is held on the way
                rig.page("window.hexactlTestTap.releaseRenewals();")
                wait_for(lambda: rig.page("return window.hexactlTestTap.heldJogs.length"), "the page's restart",
                         seen=lambda: rig.element("#jog-status").text)
                rig.client.call("stop")
                rig.page("window.hexactlTestTap.releaseJogs();")
                wait_for(lambda: "has ended (stopped)" in rig.element("#jog-status").text,
                         "the page saying the jog was stopped", seen=lambda: rig.element("#jog-status").text)
                assert "held" not in button.get_attribute("class").split()
                # (more than one when a restart held up with the renewals came to the dashboard too late: expired)
                jogs = _jogs_sent(rig)[pressed:]
                assert any(jog.get("restarts") == lapsed for jog in jogs), jogs
                assert all("renews" in jog or "restarts" in jog for jog in jogs[1:]), jogs
                renewals = sent(rig, "jog")
                rig.client.call("status")  # a round trip: any jog the page still sent has reached the service
                record = rig.status()
                assert record["jog"] is None and record["motion"] == "holding", record
                assert record["last_jog"] == {"jog": lapsed, "reason": "stopped"}
                assert sent(rig, "jog") == renewals  # none since: the button is still held
        finally:
            rig.page("window.hexactlTestTap.releaseJogs();")

    attempted(rig, scenario)
