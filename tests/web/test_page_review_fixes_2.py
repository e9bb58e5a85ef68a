"""Defects a second outside review of the dashboard found in the page, in a real headless
Chromium against a real ``hexactl serve`` (the review's numbering):

- F1: every message the page sends carries ``at`` (its ``performance.now()`` when made),
  from which the dashboard counts a command's time to live; a jog's renewals wait for the
  reply to the jog that starts it (each would start a jog of its own), and a jog dropped for
  lost live data is released with a zero velocity, not only left to the deadman;
- F2: with no live data, Enable, Play, Resume and Lock are refused in the page, saying why;
  Stop, Abort and the E-stop still go;
- F4: Escape with a drop-down list open sends the E-stop at once;
- F6: Go and the calibration's Apply are armed only with the platform at rest;
- F8: the calibration preview shows the service's message, not only the change;
- F9, F10: the Move and Sequence panels say a move or sequence is over once it is, and the
  advice in estop or fault is to reset first;
- F12: Space or Enter on a jog button says that jog needs the pointer held;
- F13: an unbalanced ``[`` is refused; no frames after Clear all read ``none``.

What the page hands its WebSocket is recorded by :data:`SENT` (installed before the page's
scripts, under the tap of ``test_validated_move``); everything is judged by the page's state,
what it sent and the service's state, never by how long anything took.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select

from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tests.web.test_page_review_fixes import (
    FILE,
    apply_enabled,
    back_to_nominal,
    calibrated,
    cleared,
    previewed_in_page,
)
from tests.web.test_validated_move import (
    TAP,
    attempted,
    go_enabled,
    live,
    move_result,
    sent,
    tap,
)

SENT = """
(() => {
  const mine = { messages: [], holdFirstJogReplyMs: 0, heldReplyAt: null, jogIds: new Set(), failEstopReplies: false,
                 estopIds: new Set() };
  window.hexactlTestSent = mine;
  const proto = WebSocket.prototype;
  const send = proto.send;
  proto.send = function (data) {
    const message = JSON.parse(data);
    mine.messages.push({ ...message, tapAt: performance.now() });
    if (message.cmd === 'jog') mine.jogIds.add(message.id);
    if (message.cmd === 'estop') mine.estopIds.add(message.id);
    return send.call(this, data);
  };
  const add = proto.addEventListener;
  proto.addEventListener = function (type, listener, options) {
    if (type !== 'message') return add.call(this, type, listener, options);
    return add.call(this, type, (event) => {
      const message = JSON.parse(event.data);
      if (mine.failEstopReplies && message.type === 'reply' && mine.estopIds.has(message.id)) {
        const reply = { ok: false, error: { code: 'loop_silent', message: 'queued, to be carried out if the loop runs again' } };
        listener(new MessageEvent('message', { data: JSON.stringify({ ...message, reply }) }));
        return;
      }
      const ms = mine.holdFirstJogReplyMs;
      if (ms > 0 && message.type === 'reply' && mine.jogIds.has(message.id)) {
        mine.holdFirstJogReplyMs = 0;
        setTimeout(() => { mine.heldReplyAt = performance.now(); listener(event); }, ms);
        return;
      }
      listener(event);
    }, options);
  };
})();
"""
"""Records every message the page hands its WebSocket (``hexactlTestSent.messages``, each
with ``tapAt``, when it was handed; the test tap's own acknowledgements of dropped telemetry
included) and holds the reply to the
next jog for ``holdFirstJogReplyMs`` (a slow first reply), handing it to the page at
``heldReplyAt``. While ``failEstopReplies``, the reply to every E-stop becomes the
``loop_silent`` failure a held-up loop gives (the E-stop itself goes to the service as sent)."""

NO_FRAMES = "work: none · tool: none · soft limits: none"


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("review-fixes-2"), before_load=SENT + TAP) as rig:
        wait_for(lambda: live(rig), "live data on the page")
        yield rig


def messages(rig: Rig, since: int = 0) -> list[dict]:
    return rig.page(f"return window.hexactlTestSent.messages.slice({since})")


def count(rig: Rig) -> int:
    return rig.page("return window.hexactlTestSent.messages.length")


def text(rig: Rig, selector: str) -> str:
    return rig.element(selector).text


def jog_button(rig: Rig, axis: str = "x"):
    return rig.shown(f'.jog[data-axis="{axis}"][data-direction="1"]')


# ---------------------------------------------------------------- F1: at, renewals, release


def test_every_message_the_page_sends_carries_when_it_was_made(rig) -> None:
    rig.at_rest_disabled()
    since, before = rig.page("return [window.hexactlTestSent.messages.length, performance.now()]")
    rig.click("#enable")
    wait_for(lambda: rig.status()["state"] == "enabled", "enabled by the page's button")
    wait_for(lambda: any(m["type"] == "ack" for m in messages(rig, since)), "an acknowledgement of telemetry")
    sent_now, after = rig.page(f"return [window.hexactlTestSent.messages.slice({since}), performance.now()]")
    assert any(m.get("cmd") == "enable" for m in sent_now), sent_now
    for message in sent_now:
        assert isinstance(message.get("at"), (int, float)) and 0 < message["at"] <= after, message
    enable = next(m for m in sent_now if m.get("cmd") == "enable")
    assert before <= enable["at"], (before, enable)  # made by the click, after the test began
    rig.at_rest_disabled()


def test_no_jog_renewal_goes_before_the_reply_to_the_jog_that_starts_it(rig) -> None:
    """Found from outside: until the first reply came back, the renewals went without
    ``renews``, so each could start a jog of its own (after a stall, after the release)."""

    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.fill("#jog-speed", 0.5)
        since = count(rig)
        rig.page("window.hexactlTestSent.holdFirstJogReplyMs = 150")  # under the 0.2 s deadman
        button = jog_button(rig)
        ActionChains(rig.driver).click_and_hold(button).perform()
        try:
            wait_for(lambda: any("renews" in m for m in messages(rig, since) if m.get("cmd") == "jog"),
                     "a renewal naming its jog", seen=lambda: messages(rig, since))
            # a slow jog's pace, under 1 % of the motion limits, in two digits (it said "0 %")
            percent = wait_for(lambda: (rig.status()["jog"] or {}).get("speed"), "the jog's pace") * 100
            assert percent < 1, percent
            pace = f", {percent:.2g} % of the motion limits)"
            wait_for(lambda: pace in text(rig, "#jog-status"), "the jog's pace said", seen=lambda: text(rig, "#jog-status"))
        finally:
            ActionChains(rig.driver).release(button).perform()
        first, *later = [m for m in messages(rig, since) if m.get("cmd") == "jog"]
        replied = rig.page("return window.hexactlTestSent.heldReplyAt")
        assert "renews" not in first and later and all(m["tapAt"] >= replied for m in later), (first, replied, later)
        wait_for(lambda: rig.status()["motion"] == "holding", "the jog braked after the release")

    attempted(rig, scenario)


def test_a_refused_jog_keeps_its_refusal_in_the_panel_and_is_not_renewed(rig) -> None:
    """Found from outside: a jog refused (a speed of 1e308) went on being sent while held,
    and the release's reply then stood in the panel for the refusal."""

    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.fill("#jog-speed", "1e308")
        cleared(rig, "#jog-status")
        since = count(rig)
        button = jog_button(rig)
        ActionChains(rig.driver).click_and_hold(button).perform()
        try:
            said = wait_for(lambda: text(rig, "#jog-status"), "the page's answer", seen=lambda: messages(rig, since))
        finally:
            ActionChains(rig.driver).release(button).perform()
        rig.client.call("status")  # a round trip: anything the page still sent has been sent
        assert "beyond 10000 (mm/s or deg/s)" in said, said
        assert "beyond 10000 (mm/s or deg/s)" in text(rig, "#jog-status"), text(rig, "#jog-status")
        jogs = [m for m in messages(rig, since) if m.get("cmd") == "jog"]
        assert len(jogs) == 1, jogs  # the refused press alone: no renewal, no release of a jog never started
        rig.fill("#jog-speed", 10)

    attempted(rig, scenario)

def test_a_jog_dropped_for_lost_live_data_is_released_with_a_zero_velocity(rig) -> None:
    """Found from outside: it was only no longer renewed, so nothing that stops it queued
    behind renewals held up in a stalled dashboard."""

    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.fill("#jog-speed", 2)
        start_x = rig.status()["pose_command"][0]
        button = jog_button(rig)
        try:
            rig.jog_held(button, lambda: rig.status()["pose_command"][0] > start_x + 0.2, "the platform jogging while held")
            since = count(rig)
            tap(rig, drop=True)
            wait_for(lambda: text(rig, "#jog-status").startswith("jog released: no live data"),
                     "the page saying why the jog stopped", seen=lambda: text(rig, "#jog-status"))
            jogs = [m for m in messages(rig, since) if m.get("cmd") == "jog"]
            assert jogs and not any(jogs[-1]["velocity"]), jogs
            wait_for(lambda: rig.status()["motion"] == "holding", "the platform at rest")
        finally:
            ActionChains(rig.driver).release(button).perform()
            tap(rig)
        wait_for(lambda: live(rig), "live data again")

    attempted(rig, scenario)


# ---------------------------------------------------------------- F2: no live data


def test_without_live_data_enable_play_resume_and_lock_are_refused_and_stop_abort_estop_go(rig) -> None:
    rig.at_rest_disabled()
    try:
        tap(rig, drop=True)
        wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss") == "telemetry", "the page's data stale")
        counts = {cmd: sent(rig, cmd) for cmd in ("enable", "play", "resume", "leg_lock")}
        rig.click("#enable")
        rig.fill("#sequence-name", "x_sweep")
        cleared(rig, "#sequence-result")
        rig.click("#play")
        said = wait_for(lambda: text(rig, "#sequence-result"), "Play's answer")
        assert "not sent: the page has no live data" in said, said
        rig.click("#resume")
        cleared(rig, "#leglock-result")
        rig.click("#leglock")
        said = wait_for(lambda: text(rig, "#leglock-result"), "Lock's answer")
        assert "not sent: the page has no live data" in said, said
        assert "no_live_data" in text(rig, "#messages")
        for selector in ("#stop", "#abort"):
            rig.click(selector)
        ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
        wait_for(lambda: sent(rig, "stop") and sent(rig, "abort") and sent(rig, "estop"), "Stop, Abort, E-stop sent")
        assert {cmd: sent(rig, cmd) for cmd in counts} == counts
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop carried out")
    finally:
        tap(rig)
        wait_for(lambda: live(rig), "live data again")
        rig.at_rest_disabled()


# ---------------------------------------------------------------- F4: Escape with a list open


@pytest.mark.parametrize("selector", ["#move-frame", "#plot-axis"])
def test_one_escape_with_a_drop_down_list_open_sends_the_estop(rig, selector) -> None:
    rig.at_rest_disabled()
    listed = rig.shown(selector)
    rig.page(f"document.querySelector('{selector}').scrollIntoView({{block: 'center'}})")
    listed.click()
    assert rig.page(f"return document.querySelector('{selector}').matches(':open')")
    presses = len(rig.page("return window.hexactlDashboard.estopEvents()"))
    ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
    wait_for(lambda: [e["what"] for e in rig.page("return window.hexactlDashboard.estopEvents()")[presses:]][:2]
             == ["pressed", "sent"], "the E-stop pressed and sent by one Escape")
    wait_for(lambda: rig.status()["state"] == "estop", "the E-stop carried out")
    rig.page(f"document.querySelector('{selector}').blur()")
    rig.at_rest_disabled()


# ---------------------------------------------------------------- F6: only at rest

OTHER_MOVE_S = 60.0
"""Another client's move, stopped once the page has answered: long enough that the page's
answer comes while it runs on a loaded host (with a 3 s move it came after the move, once
in the full suite beside another, and rightly armed Go)."""


def test_go_is_not_armed_while_another_clients_move_carries_the_platform(rig) -> None:
    """Found from outside: validated 1 s into another client's move to a fixed goal, Go was
    armed (the page compared the goal, which does not change) and ran from elsewhere."""

    def scenario() -> None:
        rig.enabled_from_the_page()
        z = rig.status()["pose_command"][2]
        for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), (0, 0, z, 0, 0, 0)):
            rig.fill(f"#move-{axis}", value)
        Select(rig.shown("#move-frame")).select_by_value("zero")
        rig.fill("#move-duration", 1)
        rig.client.call("move", pose=[0, 0, z + 20, 0, 0, 0], duration=OTHER_MOVE_S)  # another client's
        wait_for(lambda: rig.page("return window.hexactlDashboard.record.motion") == "moving", "moving on the page")
        rig.click("#move-validate")
        said = wait_for(lambda: move_result(rig) != "validating…" and move_result(rig), "the validation's answer")
        assert said.startswith("valid: duration") and "Go is not armed: the platform is moving" in said, said
        assert not go_enabled(rig)
        rig.client.call("stop")
        wait_for(lambda: rig.status()["motion"] == "holding", "the move over")
        assert not go_enabled(rig)

    attempted(rig, scenario)


def test_the_calibration_preview_shows_the_services_message(rig) -> None:
    """Found from outside: not enabled, the page showed only "change 0.000 mm", and dropped
    the service's message saying why and how far the legs would shift."""
    try:
        rig.at_rest_disabled()
        previewed_in_page(rig, calibrated(0.5, "review 2"))
        said = text(rig, "#calibration-change")
        assert "nothing is ramped" in said and "from where the active one does" in said, said
    finally:
        (rig.directory / "calibrations" / FILE).unlink(missing_ok=True)


def test_apply_is_not_armed_by_a_preview_made_while_the_platform_moves(rig) -> None:
    def scenario() -> None:
        try:
            rig.enabled_from_the_page()
            previewed_in_page(rig, calibrated(0.5, "review 2"))   # the file listed, selected; Apply armed at rest
            z = rig.status()["pose_command"][2]
            rig.client.call("move", pose=[0, 0, z + 20, 0, 0, 0], duration=OTHER_MOVE_S)  # another client's
            wait_for(lambda: rig.page("return window.hexactlDashboard.record.motion") == "moving", "moving on the page")
            cleared(rig, "#calibration-change")
            rig.click("#calibration-preview")
            said = wait_for(lambda: text(rig, "#calibration-change") not in ("", "previewing…")
                            and text(rig, "#calibration-change"), "the preview's answer")
            assert not apply_enabled(rig) and "preview again once it is at rest" in said, said
            rig.client.call("stop")
            wait_for(lambda: rig.status()["motion"] == "holding", "the move over")
            assert not apply_enabled(rig)
        finally:
            (rig.directory / "calibrations" / FILE).unlink(missing_ok=True)
            back_to_nominal(rig)

    attempted(rig, scenario)


# ---------------------------------------------------------------- F9, F10: over, and reset first


def test_the_move_line_says_the_move_is_over_after_an_estop_and_advises_reset_first(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        z = rig.status()["pose_command"][2]
        for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), (0, 0, z + 30, 0, 0, 0)):
            rig.fill(f"#move-{axis}", value)
        Select(rig.shown("#move-frame")).select_by_value("zero")
        rig.fill("#move-duration", 4)
        rig.click("#move-validate")
        wait_for(lambda: go_enabled(rig), "Go armed", seen=lambda: move_result(rig))
        rig.click("#move-go")
        wait_for(lambda: "moving" in rig.element("#move-result").get_attribute("class").split(), "the move going",
                 seen=lambda: move_result(rig))
        wait_for(lambda: rig.status()["motion"] == "moving", "the platform moving")
        ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
        wait_for(lambda: move_result(rig) == "move over: the controller is estop", "the move said over",
                 seen=lambda: move_result(rig))
        assert "moving" not in rig.element("#move-result").get_attribute("class").split()
        rig.click("#move-validate")
        said = wait_for(lambda: move_result(rig) != "validating…" and move_result(rig), "the validation's answer")
        assert "the controller is estop; reset, then enable it, then validate again" in said, said

    try:
        attempted(rig, scenario)
    finally:
        rig.at_rest_disabled()


def test_the_sequence_line_says_it_is_over_after_another_clients_stop(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.fill("#sequence-name", "x_sweep")
        rig.confirm("#play")
        wait_for(lambda: text(rig, "#sequence-result").startswith("playing"), "playing",
                 seen=lambda: text(rig, "#sequence-result"))
        wait_for(lambda: rig.status()["sequence"], "the sequence under way")
        rig.client.call("stop")
        wait_for(lambda: text(rig, "#sequence-result").startswith("sequence over: aborted"), "the sequence said over",
                 seen=lambda: text(rig, "#sequence-result"))
        wait_for(lambda: rig.status()["motion"] == "holding", "at rest")

    attempted(rig, scenario)


def test_the_sequence_line_says_how_far_a_leg_lock_moves_the_waypoints(rig) -> None:
    """Found from outside: a sequence played with a leg locked ran to waypoints projected
    onto the lock, up to 25 mm from the file's, and the page did not say so."""
    def scenario() -> None:
        (rig.directory / "sequences" / "steps.toml").write_text(
            'name = "steps"\n[[waypoint]]\npose = [0, 0, 6, 0, 0, 0]\ndwell = 5\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\n')
        rig.enabled_from_the_page()
        rig.client.call("leg_lock", leg=3)
        try:
            rig.fill("#sequence-name", "steps.toml")
            rig.confirm("#play")
            said = wait_for(lambda: "steps" in text(rig, "#sequence-result") and text(rig, "#sequence-result"),
                            "the play's reply", seen=lambda: text(rig, "#sequence-result"))
            assert re.fullmatch(r"playing steps: steps, 2 waypoints, \d+\.\d s; projected onto the locked leg: "
                                r"waypoints move by up to [1-9]\d*\.\d{3} mm", said), said
            wait_for(lambda: rig.status()["sequence"] is None and rig.status()["motion"] == "holding", "played")
        finally:
            rig.client.request("leg_unlock")

    try:
        attempted(rig, scenario)
    finally:
        rig.at_rest_disabled()


# ---------------------------------------------------------------- F12: the keyboard on a jog button


@pytest.mark.parametrize("key", [Keys.SPACE, Keys.ENTER])
def test_space_or_enter_on_a_jog_button_says_jog_needs_the_pointer_held(rig, key) -> None:
    jogs = sent(rig, "jog")
    cleared(rig, "#jog-status")
    button = jog_button(rig)
    rig.driver.execute_script("arguments[0].focus()", button)
    ActionChains(rig.driver).send_keys(key).perform()
    said = wait_for(lambda: text(rig, "#jog-status"), "the page's answer")
    assert "the keyboard does not jog" in said and "pressing and holding" in said, said
    assert "held" not in button.get_attribute("class").split()
    assert sent(rig, "jog") == jogs


# ---------------------------------------------------------------- F13: frames


def test_an_unbalanced_bracket_is_refused_and_no_frames_read_none_after_clear_all(rig) -> None:
    rig.client.call("clear_frames")
    for selector in ("#frame-tool", "#soft-lower", "#soft-upper", "#soft-max-tilt"):
        rig.fill(selector, "")
    before = sent(rig, "set_frames")
    rig.fill("#frame-work", "[1,2,3,4,5,6")
    cleared(rig, "#frames-result")
    rig.click("#frames-apply")
    said = wait_for(lambda: text(rig, "#frames-result"), "the page's answer")
    assert said.startswith("work frame: unbalanced bracket") and "nothing was sent" in said, said
    rig.client.call("status")  # a round trip: a set_frames the page sent has reached the service
    assert sent(rig, "set_frames") == before
    rig.fill("#frame-work", "[1,2,3,4,5,6]")
    rig.click("#frames-apply")
    wait_for(lambda: rig.client.call("frames")["frames"]["work"] == [1, 2, 3, 4, 5, 6], "the work frame set")
    rig.confirm("#frames-clear")
    wait_for(lambda: text(rig, "#frames-current") == NO_FRAMES, "no frames, said as before any was set",
             seen=lambda: text(rig, "#frames-current"))
    rig.fill("#frame-work", "")
