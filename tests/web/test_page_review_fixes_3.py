"""Defects a third outside review of the dashboard found in the page, in a real headless
Chromium against a real ``hexactl serve``:

- the plots drew a straight line across an outage (the service stopped for 14 s: a smooth
  "move" from 94 mm to 0 that never happened);
- an E-stop whose reply failed (the loop held up: queued) and that the loop then carried
  out kept "E-STOP NOT CONFIRMED" on screen beside the state pill reading estop;
- the Messages list merged two E-stops a reset apart into one line, the first's time lost;
- the calibration preview still offered "would be accepted" after Apply had loaded it;
- a jog speed of 0 was sent, and answered "nothing to release";
- after an E-stop, reset and enable by another client, the Move line still advised
  "reset, then enable it".

Judged by the page's state, what it sent and the service's state, never by how long
anything took.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys

from hexactl.adapters.files.geometry_file import geometry_id
from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tests.web import test_page_review_fixes as preview
from tests.web import test_validated_move as moves
from tests.web.test_page_review_fixes_2 import SENT

@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("review-fixes-3"),
                           before_load=SENT + moves.TAP) as rig:
        wait_for(lambda: moves.live(rig), "live data on the page")
        yield rig


def messages(rig: Rig, key_start: str) -> list[str]:
    """The Messages list's lines whose key (``cmd: code|message``) starts with ``key_start``, newest first."""
    return rig.page(f"return [...document.querySelectorAll('#messages li')]"
                    f".filter(li => li.dataset.key.startsWith({key_start!r})).map(li => li.textContent)")


def test_the_plots_break_their_lines_where_no_records_came(rig) -> None:
    history = rig.driver.execute_async_script("""
        const done = arguments[arguments.length - 1];
        import('/static/plots.js').then(({ History }) => {
          const h = new History();
          const record = (t, z) => ({ t, pose_command: [0, 0, z, 0, 0, 0], pose_measured: [0, 0, z, 0, 0, 0],
                                      leg_setpoints: [1, 2, 3, 4, 5, 6], leg_feedback: [1, 2, 3, 4, 5, 6],
                                      loop: { lateness_us: { p99: 5 }, compute_us: { p99: 7 } } });
          [0, 0.02, 0.04].forEach((t) => h.push(record(t, 94)));
          h.push(record(14.04, -0.6));            // the service back after 14 s
          h.push(record(14.06, -0.6));
          h.push(record(14.08, -0.6));
          h.push(record(14.1, -0.6));             // a record 10 ms early: no gap
          h.push(record(14.7, -0.6));             // 0.6 s late (30 intervals): an outage too
          h.push(record(15.5, -0.6));             // 0.8 s more, right after: the outage before sets no interval
          done({ t: h.t, z: h.pc[2], lat: h.lat, csv: h.toCSV().trim().split('\\n') });
        });
    """)
    assert history["t"] == pytest.approx([0, 0.02, 0.04, 7.04, 14.04, 14.06, 14.08, 14.1, 14.4, 14.7, 15.1, 15.5]), \
        history["t"]
    assert history["z"] == [94, 94, 94, None, -0.6, -0.6, -0.6, -0.6, None, -0.6, None, -0.6], history["z"]
    assert history["lat"][3] is None and history["lat"][8] is None and history["lat"][10] is None
    assert len(history["csv"]) == 1 + 9 and not any(",,,," in line for line in history["csv"][1:]), history["csv"]


def test_a_queued_estop_the_loop_carries_out_clears_the_not_confirmed_banner_saying_so(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.page("window.hexactlTestSent.failEstopReplies = true")
        try:
            rig.click("#estop")
            wait_for(lambda: rig.status()["state"] == "estop", "the E-stop carried out")
            events = lambda: rig.page("return window.hexactlDashboard.estopEvents()")  # noqa: E731
            wait_for(lambda: any(e["what"] == "cleared" for e in events()), "the banner cleared by the records",
                     seen=events)
        finally:
            rig.page("window.hexactlTestSent.failEstopReplies = false")
        whats = [e["what"] for e in events()]
        assert "reply-failed" in whats and "warning" in whats, whats  # the failed reply did raise it
        cleared_by = [e for e in events() if e["what"] == "cleared"][-1]
        assert cleared_by["detail"].startswith("in force: event "), cleared_by
        assert not rig.page("return window.hexactlDashboard.estopWarning")
        assert rig.element("#estop-warning").get_attribute("hidden") is not None
        said = messages(rig, "estop: in force|")
        assert said and "the controller is in estop: event " in said[0], said

    rig.scenario(scenario)


def _presses(rig: Rig) -> list[int]:
    return [e["press"] for e in rig.page("return window.hexactlDashboard.estopEvents()") if e["what"] == "pressed"]


def test_the_estop_button_stops_on_the_press_not_the_release(rig) -> None:
    """Found from outside: sent on click, the E-stop needed the release over the button: an
    operator who pressed and slid off it sent nothing, and one holding it down waited for
    the release. Now the press sends it, once; the keyboard's Enter on the button too."""
    def scenario() -> None:
        rig.enabled_from_the_page()
        before = len(_presses(rig))
        button = rig.shown("#estop")
        hold = ActionChains(rig.driver).click_and_hold(button)
        hold.perform()
        try:
            wait_for(lambda: rig.status()["state"] == "estop", "the E-stop in force, the button still held")
            # and the tab says so among other tabs (found from outside: "hexactl dashboard" whatever the state)
            wait_for(lambda: rig.driver.title == "ESTOP · hexactl dashboard", "the tab's title", seen=lambda: rig.driver.title)
            ActionChains(rig.driver).move_by_offset(-300, 200).perform()
        finally:
            ActionChains(rig.driver).release().perform()
        assert len(_presses(rig)) == before + 1  # pressed once: the slide and release send nothing more
        rig.client.call("reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        ActionChains(rig.driver).click(button).perform()  # a whole click is one press, one E-stop
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop of a click")
        assert len(_presses(rig)) == before + 2
        rig.client.call("reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        rig.page("document.getElementById('estop').focus()")
        enter = {"key": "Enter", "code": "Enter", "windowsVirtualKeyCode": 13}
        rig.driver.execute_cdp_cmd("Input.dispatchKeyEvent", {"type": "keyDown", "text": "\r", **enter})
        for _ in range(5):  # Enter held: the keyboard's auto-repeat (found from outside: an E-stop each)
            rig.driver.execute_cdp_cmd("Input.dispatchKeyEvent", {"type": "keyDown", "text": "\r", "autoRepeat": True, **enter})
        rig.driver.execute_cdp_cmd("Input.dispatchKeyEvent", {"type": "keyUp", **enter})
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop of Enter on the button")
        rig.client.call("status")  # a round trip: whatever the page sent has reached the service
        assert len(_presses(rig)) == before + 3
        rig.client.call("reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        rig.page("document.activeElement && document.activeElement.blur()")
        x, y = rig.page("const r = document.getElementById('estop').getBoundingClientRect(); "
                        "return [r.x + r.width / 2, r.y + r.height / 2]")

        def mouse(kind: str, button: str, buttons: int) -> None:
            rig.driver.execute_cdp_cmd("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": button,
                                                                    "buttons": buttons, "clickCount": 1})
        # A left press while the right button is held (found from outside: no pointerdown, no E-stop)
        mouse("mousePressed", "right", 2), mouse("mousePressed", "left", 3)
        mouse("mouseReleased", "left", 2), mouse("mouseReleased", "right", 0)
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop of a left press with the right held")
        assert len(_presses(rig)) == before + 4

    rig.scenario(scenario)


def test_play_clear_all_and_roll_back_ask_for_a_second_press_saying_what_they_would_do(rig) -> None:
    """Found from outside: Play (its name filled in: x_sweep, 32 s to x -600 mm), Roll back
    and Clear all acted at one click, beside the Move panel that validates first."""
    def scenario() -> None:
        rig.enabled_from_the_page()
        assert rig.page("return document.getElementById('sequence-name').defaultValue") == ""  # none filled in
        rig.client.call("set_frames", work=[0, 0, 0, 0, 0, 5])
        work = lambda: rig.client.call("frames")["frames"]["work"]  # noqa: E731
        plays, clears, rollbacks = (moves.sent(rig, cmd) for cmd in ("play", "clear_frames", "rollback_calibration"))
        rig.click("#frames-clear")
        said = wait_for(lambda: rig.element("#frames-result").text, "Clear all's question")
        assert said.startswith("clears the work frame, the tool frame and every soft limit (now: ") and \
            'Press "Confirm: Clear all" within 10 s' in said, said
        rig.click("#calibration-rollback")
        said = wait_for(lambda: rig.element("#calibration-result").text, "Roll back's question")
        assert said.startswith("returns to the calibration active before the last load"), said
        rig.fill("#sequence-name", "x_sweep")
        rig.click("#play")
        said = wait_for(lambda: "ending at" in rig.element("#sequence-result").text and rig.element("#sequence-result").text,
                        "Play's question", seen=lambda: rig.element("#sequence-result").text)
        assert said.startswith("x_sweep: ") and " waypoints, " in said and 'Press "Confirm: Play"' in said, said
        rig.fill("#sequence-name", "y_rotation")  # another sequence than the one told: asked again, not played
        rig.click("#play")
        wait_for(lambda: rig.element("#sequence-result").text.startswith("y_rotation: "), "asked again")
        rig.client.call("status")  # a round trip: whatever the page sent has reached the service
        assert (moves.sent(rig, "play"), moves.sent(rig, "clear_frames"), moves.sent(rig, "rollback_calibration")) == \
            (plays, clears, rollbacks)
        assert work() == [0, 0, 0, 0, 0, 5] and rig.status()["sequence"] is None
        # Found from outside: a double-click, a held Enter and frames changed between the presses each played
        # a double-click, its second click marked as such whenever it comes (a busy host may space them)
        cx, cy = rig.driver.execute_script("const r = arguments[0].getBoundingClientRect(); "
                                           "return [r.x + r.width / 2, r.y + r.height / 2]", rig.shown("#frames-clear"))
        for count in (1, 2):
            for kind in ("mousePressed", "mouseReleased"):
                rig.driver.execute_cdp_cmd("Input.dispatchMouseEvent", {"type": kind, "x": cx, "y": cy, "button": "left",
                                                                        "buttons": 1 if kind == "mousePressed" else 0,
                                                                        "clickCount": count})
        rig.fill("#sequence-name", "compound")  # Play is armed for y_rotation: another name asks first
        rig.page("document.getElementById('play').focus()")
        enter = {"key": "Enter", "code": "Enter", "windowsVirtualKeyCode": 13}
        for repeat in (False, True, True, True):
            rig.driver.execute_cdp_cmd("Input.dispatchKeyEvent", {"type": "keyDown", "text": "\r", "autoRepeat": repeat,
                                                                  **enter})
        rig.driver.execute_cdp_cmd("Input.dispatchKeyEvent", {"type": "keyUp", **enter})
        rig.client.call("status")  # a round trip: whatever the page sent has reached the service
        assert moves.sent(rig, "play") == plays and moves.sent(rig, "clear_frames") == clears
        wait_for(lambda: rig.element("#sequence-result").text.startswith("compound: "), "Enter's question")
        rig.client.call("set_frames", work=[0, 0, 0, 0, 0, 6])  # another client, between the question and the press
        wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.work[5]") == 6, "the page told")
        preview.cleared(rig, "#sequence-result")
        time.sleep(0.45)  # past the 0.4 s in which a press confirms nothing
        rig.click("#play")
        wait_for(lambda: rig.element("#sequence-result").text.startswith("compound: "), "asked again")
        assert moves.sent(rig, "play") == plays
        time.sleep(0.45)
        rig.click("#play")  # the second press on what was described: played
        wait_for(lambda: rig.status()["sequence"] is not None or rig.status()["last_sequence"], "played")
        assert moves.sent(rig, "play") == plays + 1
        rig.client.call("abort")
        wait_for(lambda: rig.status()["motion"] == "holding", "at rest")
        rig.confirm("#frames-clear")
        wait_for(lambda: not any(work() or []), "cleared on the second press (a zero frame is none)", seen=work)

    try:
        rig.scenario(scenario)
    finally:
        rig.client.request("clear_frames")


def test_two_estops_a_reset_apart_are_two_lines_each_with_its_time(rig) -> None:
    def scenario() -> None:
        rig.at_rest_disabled()
        before = len(messages(rig, "estop: ok|"))
        rig.click("#estop")
        wait_for(lambda: len(messages(rig, "estop: ok|")) == before + 1, "the first E-stop confirmed")
        rig.click("#reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
        wait_for(lambda: len(messages(rig, "estop: ok|")) == before + 2, "the second E-stop, a line of its own",
                 seen=lambda: messages(rig, "estop"))
        assert not any("×" in line for line in messages(rig, "estop: ok|")), messages(rig, "estop")

    rig.scenario(scenario)


def test_apply_clears_the_calibration_preview_it_used(rig) -> None:
    small = preview.calibrated(0.2, "review-3 small")

    def scenario() -> None:
        rig.at_rest_disabled()
        try:
            preview.previewed_in_page(rig, small)
            preview.cleared(rig, "#calibration-result")
            rig.click("#calibration-apply")
            wait_for(lambda: rig.status()["calibration_id"] == geometry_id(small), "the calibration applied")
            change = rig.element("#calibration-change")
            assert change.text == "used by Apply (below): preview again for another change", change.text
            assert not preview.apply_enabled(rig)
            rig.confirm("#calibration-rollback")
            wait_for(lambda: rig.status()["calibration_id"] == preview.NOMINAL_ID, "rolled back")
            assert "would be accepted" not in change.text and not preview.apply_enabled(rig), change.text
        finally:
            preview.back_to_nominal(rig)

    rig.scenario(scenario)


def test_a_jog_speed_of_zero_sends_no_jog_and_says_why(rig) -> None:
    rig.at_rest_disabled()
    wait_for(lambda: moves.live(rig), "live data on the page")
    before = moves.sent(rig, "jog")
    rig.fill("#jog-speed", "0")
    preview.cleared(rig, "#jog-status")
    button = rig.shown('.jog[data-axis="x"][data-direction="1"]')
    ActionChains(rig.driver).click_and_hold(button).perform()
    try:
        said = wait_for(lambda: rig.element("#jog-status").text, "the page's answer")
    finally:
        ActionChains(rig.driver).release(button).perform()
    assert said == "jog speed: 0 moves nothing: type a speed > 0 in mm/s, °/s; not sent", said
    rig.client.call("status")
    assert moves.sent(rig, "jog") == before
    rig.fill("#jog-speed", 10)


def test_the_move_line_stops_advising_reset_once_the_controller_is_enabled_again(rig) -> None:
    def scenario() -> None:
        moves.ready_in_frames(rig)
        moves.validated_in_page(rig, [0, 0, 6, 0, 0, 0], "zero")
        rig.client.call("estop")  # another client
        wait_for(lambda: not moves.go_enabled(rig), "Go withdrawn", seen=lambda: moves.move_result(rig))
        assert moves.move_result(rig) == \
            "the controller is estop: Go is withdrawn; reset, then enable it, then validate again"
        rig.client.call("reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        rig.client.call("enable")
        wait_for(lambda: rig.element("#state").text.strip() == "enabled", "the page showing enabled")
        wait_for(lambda: moves.move_result(rig) == "Go was withdrawn when the controller went estop: validate again",
                 "the Move line in the past tense", seen=lambda: moves.move_result(rig))
        assert not moves.go_enabled(rig)

    moves.attempted(rig, scenario)


def test_an_invalid_requests_problems_are_shown_once_in_words(rig) -> None:
    """Found from outside: ``duration: Input should be greater than 0`` came twice, the
    second time as JSON (``• {"field":"duration","problem":…}``)."""
    described = rig.driver.execute_async_script("""
        const done = arguments[arguments.length - 1];
        import('/static/controls.js').then(({ describeError }) => done([
          describeError({ code: 'invalid_request', message: 'validate_pose: duration: Input should be greater than 0',
                          details: [{ field: 'duration', problem: 'Input should be greater than 0' }] }),
          describeError({ code: 'invalid_request', message: 'move: speed: too fast',
                          details: [{ field: 'speed', problem: 'too fast' }, { field: 'pose[2]', problem: 'not a number' },
                                    { field: '', problem: 'give one of them' }] }),
        ]));
    """)
    assert described[0] == "invalid_request: validate_pose: duration: Input should be greater than 0", described[0]
    assert described[1] == "invalid_request: move: speed: too fast\n  • pose[2]: not a number\n  • give one of them", \
        described[1]
