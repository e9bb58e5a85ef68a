"""Defects an outside review of the dashboard found, in a real headless Chromium against a
real ``hexactl serve`` (the reviewer's reproductions: F2–F5):

- F3: an empty entry or a lone ``-`` among the six soft limits removed that bound, and
  ``0x10`` was 16 (``Number``'s rules): only ``null``/``none`` remove a bound, anything
  that is not a plain decimal number is refused, naming the field and the entry, and
  nothing is sent; the other numeric inputs likewise;
- F5: a validated move stayed armed through an E-stop, a reset and Enable: one click on Go
  started it; Go is now withdrawn whenever the controller leaves ``enabled``;
- F4: after a service restart on the same host (the records' ``t``, the host's monotonic
  clock, does not go back) the Events panel missed bursts: the event numbers going back
  is a new service too, whose events are fetched from its first;
- F2: a calibration previewed, then its file rewritten: Apply loaded the new one; Apply now
  sends the id previewed (``expected_id``) and the service refuses another; the preview is
  withdrawn when the state or the calibration in force changes.

What the page sends is counted by the tap of ``test_validated_move`` (installed before the
page's scripts); everything is judged by the page's state and the service's, never by how
long anything took (the waits' bounds only turn a hang into a failure).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from tests.reliability.support import enable
from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tests.web.test_validated_move import (TAP, assert_not_moved, attempted, go_enabled, move_result,
                                           ready_in_frames, sent, tap, validated_in_page)
from tools.browser import dashboard, headless_chromium
from tools.serving import free_port, serve, terminate

AXES = ("x", "y", "z", "roll", "pitch", "yaw")
LOWER = [-100.0, -100.0, -100.0, -10.0, -10.0, -10.0]


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("review-fixes"), before_load=TAP) as rig:
        yield rig


def result(rig: Rig, selector: str) -> str:
    return rig.element(selector).text


def cleared(rig: Rig, selector: str) -> None:
    """The result element emptied, so that the next text in it is the next action's."""
    rig.driver.execute_script("arguments[0].textContent = ''", rig.element(selector))


def soft_limits(rig: Rig) -> dict:
    return rig.client.call("frames")["frames"]["soft_limits"]


# ---------------------------------------------------------------- F3: numbers typed


@pytest.mark.parametrize(("typed", "entry"), [
    ("-50, , -100, -10, -10, -10", "entry 2 (y) is empty"),
    ("-50, -100, -100, -10, -, -10", 'entry 5 (pitch) "-" is not a number'),
    ("0x10, -100, -100, -10, -10, -10", 'entry 1 (x) "0x10" is not a number'),
    ("-50, 0b1, -100, -10, -10, -10", 'entry 2 (y) "0b1" is not a number'),
    ("-50, -100, 1e, -10, -10, -10", 'entry 3 (z) "1e" is not a number'),
    ("-50, -100, -100, -10, -10, Infinity", 'entry 6 (yaw) "Infinity" is not a number'),
    (", , , , , ", "entry 1 (x) is empty"),
])
def test_a_soft_limit_entry_that_is_not_a_number_is_refused_naming_it_and_nothing_is_sent(rig, typed, entry) -> None:
    """Found from outside: an empty or '-' entry (a negative number begun) removed that
    bound, silently; '0x10' was 16. Only null/none remove a bound."""
    rig.client.call("clear_frames")
    rig.client.call("set_frames", soft_limits={"lower": LOWER})
    wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.soft_limits.lower") == LOWER,
             "the soft limits on the page")
    before = sent(rig, "set_frames")
    try:
        for selector in ("#frame-work", "#frame-tool", "#soft-upper", "#soft-max-tilt"):
            rig.fill(selector, "")
        rig.fill("#soft-lower", typed)
        cleared(rig, "#frames-result")
        rig.click("#frames-apply")
        said = wait_for(lambda: result(rig, "#frames-result"), "the page's answer")
        assert said.startswith("soft lower bounds: "), said
        assert entry in said, said
        assert "nothing was sent" in said, said
        assert "refused" in rig.element("#frames-result").get_attribute("class").split()
        rig.client.call("status")  # a round trip: a set_frames the page sent has reached the service
        assert sent(rig, "set_frames") == before
        assert soft_limits(rig)["lower"] == LOWER
    finally:
        rig.client.call("clear_frames")


def test_null_and_none_remove_a_bound_and_decimal_numbers_are_taken(rig) -> None:
    rig.client.call("clear_frames")
    rig.client.call("set_frames", soft_limits={"lower": LOWER})
    try:
        for selector in ("#frame-work", "#frame-tool", "#soft-upper", "#soft-max-tilt"):
            rig.fill(selector, "")
        rig.fill("#soft-lower", "-500.5, null, None, -2.5e1, +-20, -.5e2")
        cleared(rig, "#frames-result")
        rig.click("#frames-apply")
        # "+-20" is not a number: refused, nothing sent
        said = wait_for(lambda: result(rig, "#frames-result"), "the page's answer")
        assert 'entry 5 (pitch) "+-20" is not a number' in said, said
        rig.fill("#soft-lower", "-500.5, null, None, -2.5e1, -20, -.5e2")  # bounds well below the platform
        rig.click("#frames-apply")
        expected = [-500.5, None, None, -25.0, -20.0, -50.0]
        wait_for(lambda: soft_limits(rig)["lower"] == expected, f"the service's lower bounds {expected}",
                 seen=lambda: (soft_limits(rig), result(rig, "#frames-result")))
    finally:
        rig.client.call("clear_frames")


@pytest.mark.parametrize(("selector", "typed", "said"), [
    ("#frame-work", "0x10, 0, 300, 0, 0, 0", 'work frame: entry 1 (x) "0x10" is not a number'),
    ("#frame-tool", "0, 0, 300, 0, null, 0", 'tool frame: entry 5 (pitch) "null" is not a number'),
    ("#frame-tool", "0, 0, 300, 0, , 0", "tool frame: entry 5 (pitch) is empty"),
    ("#soft-max-tilt", "0x10", 'max tilt: "0x10" is not a number'),
    ("#soft-max-tilt", "-", 'max tilt: "-" is not a number'),
])
def test_the_frames_and_the_tilt_take_only_decimal_numbers(rig, selector, typed, said) -> None:
    rig.client.call("clear_frames")
    before, in_force = sent(rig, "set_frames"), rig.client.call("frames")["frames"]
    for other in ("#frame-work", "#frame-tool", "#soft-lower", "#soft-upper", "#soft-max-tilt"):
        rig.fill(other, "")
    rig.fill(selector, typed)
    cleared(rig, "#frames-result")
    rig.click("#frames-apply")
    shown = wait_for(lambda: result(rig, "#frames-result"), "the page's answer")
    assert shown.startswith(said) and "nothing was sent" in shown, shown
    rig.client.call("status")
    assert sent(rig, "set_frames") == before
    assert rig.client.call("frames")["frames"] == in_force


def test_an_empty_move_input_is_refused_not_taken_for_zero(rig) -> None:
    """Number('') is 0: an axis left empty was a move to 0 on it."""
    rig.at_rest_disabled()
    for axis, value in zip(AXES, (5, 0, 10, 0, 0, 0)):
        rig.fill(f"#move-{axis}", value)
    rig.fill("#move-x", "")
    before = sent(rig, "validate_pose")
    cleared(rig, "#move-result")
    rig.click("#move-validate")
    said = wait_for(lambda: move_result(rig), "the page's answer")
    assert said.startswith("x: empty"), said
    rig.client.call("status")
    assert sent(rig, "validate_pose") == before
    assert not go_enabled(rig)


@pytest.mark.parametrize(("typed", "said"), [("1,5", 'x: "1,5" is not a number (a decimal point, not a comma: 1.5)'),
                                             ("0x10", 'x: "0x10" is not a number'),
                                             ("1.2.3", 'x: "1.2.3" is not a number')])
def test_a_move_typed_with_a_comma_is_refused_not_read_as_another_number(rig, typed: str, said: str) -> None:
    """Found from outside: the fields were number inputs, and the browser dropped what it
    refused as it was typed: "1,5" became 15 (a goal ten times as far), "1.2.3" 1.23."""
    rig.at_rest_disabled()
    for axis in AXES:
        rig.fill(f"#move-{axis}", 0)
    rig.fill("#move-x", typed)
    assert rig.element("#move-x").get_attribute("value") == typed  # as typed: nothing dropped
    before = sent(rig, "validate_pose")
    cleared(rig, "#move-result")
    rig.click("#move-validate")
    shown = wait_for(lambda: move_result(rig), "the page's answer")
    assert shown.startswith(said) and "nothing was sent" in shown, shown
    rig.client.call("status")
    assert sent(rig, "validate_pose") == before
    assert not go_enabled(rig)

def test_a_jog_speed_that_is_not_a_number_sends_no_jog(rig) -> None:
    """Number('') is 0: an empty speed sent a jog at 0 (a jog the operator did not mean)."""
    rig.at_rest_disabled()
    wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss === null"), "live data on the page")
    before = sent(rig, "jog")
    rig.fill("#jog-speed", "")
    cleared(rig, "#jog-status")
    button = rig.shown('.jog[data-axis="x"][data-direction="1"]')
    ActionChains(rig.driver).click_and_hold(button).perform()
    try:
        said = wait_for(lambda: result(rig, "#jog-status"), "the page's answer")
    finally:
        ActionChains(rig.driver).release(button).perform()
    assert said.startswith("jog speed: empty") and "not sent" in said, said
    rig.client.call("status")
    assert sent(rig, "jog") == before
    rig.fill("#jog-speed", 10)


# ---------------------------------------------------------------- F5: Go through an E-stop

GOAL = [0, 0, 6, 0, 0, 0]


def test_the_pages_estop_withdraws_go_and_reset_and_enable_do_not_bring_it_back(rig) -> None:
    """Found from outside: validated, then Escape (E-stop), Reset and Enable: Go was still
    enabled, and one click started the move validated before the E-stop."""
    def scenario() -> None:
        before = ready_in_frames(rig)
        validated_in_page(rig, GOAL, "zero")
        moves = sent(rig, "move")
        ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
        wait_for(lambda: not go_enabled(rig), "Go withdrawn", seen=lambda: move_result(rig))
        assert "Go is withdrawn" in move_result(rig) and "validate again" in move_result(rig), move_result(rig)
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop latched")
        rig.click("#reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        rig.click("#enable")
        wait_for(lambda: rig.element("#state").text.strip() == "enabled", "the page showing enabled")
        assert not go_enabled(rig), move_result(rig)
        rig.click("#move-go")  # a disabled button: nothing happens
        rig.client.call("status")
        assert sent(rig, "move") == moves
        assert_not_moved(rig, before)

    attempted(rig, scenario)


def test_another_clients_disable_withdraws_go(rig) -> None:
    def scenario() -> None:
        ready_in_frames(rig)
        validated_in_page(rig, GOAL, "zero")
        moves = sent(rig, "move")
        rig.client.call("disable")
        wait_for(lambda: not go_enabled(rig), "Go withdrawn", seen=lambda: move_result(rig))
        assert "the controller is disabled" in move_result(rig), move_result(rig)
        enable(rig.client)
        wait_for(lambda: rig.element("#state").text.strip() == "enabled", "the page showing enabled")
        assert not go_enabled(rig)
        assert sent(rig, "move") == moves

    attempted(rig, scenario)


def test_an_estop_reset_and_enable_the_page_never_saw_as_a_state_withdraw_go_by_their_events(rig) -> None:
    """The page handles the newest record at each frame it draws: a short E-stop, reset and
    Enable may never show in the state it sees. Here the tap holds the records' state at
    enabled; their events say what happened."""
    def scenario() -> None:
        ready_in_frames(rig)
        validated_in_page(rig, GOAL, "zero")
        moves = sent(rig, "move")
        rig.page("window.hexactlTestTap.recordFields = {state: 'enabled'};")
        try:
            rig.client.call("estop")
            rig.client.call("reset")
            enable(rig.client)
            wait_for(lambda: not go_enabled(rig), "Go withdrawn", seen=lambda: move_result(rig))
            assert "validate again" in move_result(rig), move_result(rig)
            assert sent(rig, "move") == moves
        finally:
            tap(rig)

    attempted(rig, scenario)


def test_a_move_validated_while_disabled_does_not_arm_go(rig) -> None:
    def scenario() -> None:
        rig.at_rest_disabled()
        wait_for(lambda: rig.element("#state").text.strip() == "disabled", "the page showing disabled")
        for axis, value in zip(AXES, GOAL):
            rig.fill(f"#move-{axis}", value)
        rig.fill("#move-duration", 1)
        cleared(rig, "#move-result")
        rig.click("#move-validate")
        wait_for(lambda: move_result(rig) not in ("", "validating…"), "the validation's answer")
        assert move_result(rig).startswith("valid: duration"), move_result(rig)
        assert "Go is not armed: the controller is disabled" in move_result(rig), move_result(rig)
        assert not go_enabled(rig)
        rig.click("#enable")
        wait_for(lambda: rig.element("#state").text.strip() == "enabled", "the page showing enabled")
        assert not go_enabled(rig)

    attempted(rig, scenario)


# ---------------------------------------------------------------- F2: preview, then Apply

def calibrated(mm: float, name: str):  # noqa: ANN201
    nominal = load_geometry(default_config_path())
    return nominal.model_copy(update={"name": name, "zero_lengths": tuple(x + mm for x in nominal.zero_lengths)})


NOMINAL_ID = geometry_id(load_geometry(default_config_path()))
FILE = "review-preview.toml"


def apply_enabled(rig: Rig) -> bool:
    return rig.element("#calibration-apply").is_enabled()


def back_to_nominal(rig: Rig) -> None:
    while rig.status()["calibration_id"] != NOMINAL_ID:
        rig.client.call("rollback_calibration")


def previewed_in_page(rig: Rig, geometry) -> None:  # noqa: ANN001
    """``geometry`` written to :data:`FILE`, listed, selected and previewed: Apply enabled."""
    (rig.directory / "calibrations" / FILE).write_text(geometry_to_toml(geometry))
    rig.click("#calibration-refresh")
    wait_for(lambda: any(o.get_attribute("value") == FILE for o in Select(rig.element("#calibration-files")).options),
             "the file in the list")
    Select(rig.shown("#calibration-files")).select_by_value(FILE)
    cleared(rig, "#calibration-change")
    rig.click("#calibration-preview")
    change = rig.element("#calibration-change")
    wait_for(lambda: "valid" in change.get_attribute("class").split(), "the preview", seen=lambda: change.text)
    assert geometry_id(geometry) in change.text, change.text
    assert apply_enabled(rig)


def test_apply_loads_only_what_was_previewed_a_file_rewritten_since_is_refused(rig) -> None:
    """Found from outside: previewed (0.2 mm), the file rewritten (2 mm), Apply loaded the
    2 mm one: Apply sent only the file's name."""
    small, big = calibrated(0.2, "review small"), calibrated(2.0, "review big")

    def scenario() -> None:
        rig.at_rest_disabled()
        try:
            previewed_in_page(rig, small)
            (rig.directory / "calibrations" / FILE).write_text(geometry_to_toml(big))  # another client
            cleared(rig, "#calibration-result")
            rig.click("#calibration-apply")
            said = wait_for(lambda: result(rig, "#calibration-result"), "Apply's answer")
            assert said.startswith("changed_since_validation: "), said
            assert geometry_id(small) in said and geometry_id(big) in said and "preview it again" in said, said
            assert rig.status()["calibration_id"] == NOMINAL_ID
            assert not apply_enabled(rig)
            # previewed again, the file as it is now is what Apply loads
            previewed_in_page(rig, big)
            rig.click("#calibration-apply")
            wait_for(lambda: rig.status()["calibration_id"] == geometry_id(big), "the calibration previewed, applied")
        finally:
            back_to_nominal(rig)

    rig.scenario(scenario)


def test_a_preview_is_withdrawn_when_the_state_changes(rig) -> None:
    def scenario() -> None:
        rig.at_rest_disabled()
        wait_for(lambda: rig.element("#state").text.strip() == "disabled", "the page showing disabled")
        previewed_in_page(rig, calibrated(0.2, "review small"))
        before = sent(rig, "load_calibration")
        enable(rig.client)
        wait_for(lambda: not apply_enabled(rig), "Apply withdrawn", seen=lambda: result(rig, "#calibration-change"))
        said = result(rig, "#calibration-change")
        assert "the controller is enabled" in said and "preview again" in said, said
        assert sent(rig, "load_calibration") == before
        assert rig.status()["calibration_id"] == NOMINAL_ID

    rig.scenario(scenario)


def test_a_preview_is_withdrawn_when_another_client_loads_a_calibration(rig) -> None:
    other = calibrated(0.3, "another client's")

    def scenario() -> None:
        rig.at_rest_disabled()
        try:
            previewed_in_page(rig, calibrated(0.2, "review small"))
            rig.client.call("load_calibration", toml=geometry_to_toml(other))
            wait_for(lambda: not apply_enabled(rig), "Apply withdrawn", seen=lambda: result(rig, "#calibration-change"))
            said = result(rig, "#calibration-change")
            assert f"the calibration in force changed (now {geometry_id(other)})" in said, said
            assert "preview again" in said, said
        finally:
            back_to_nominal(rig)

    rig.scenario(scenario)


# ---------------------------------------------------------------- F4: events after a restart

ANN = "ann at the bench"


def page_events(driver) -> list[dict]:  # noqa: ANN001
    return driver.execute_script("return window.hexactlDashboard.events()")


def listed(driver, events: list[dict]) -> bool:  # noqa: ANN001
    shown = {(e["t"], e["code"]) for e in page_events(driver)}
    return all((e["t"], e["code"]) in shown for e in events)


def stops_unseen(driver, client: HexactlClient, count: int) -> None:  # noqa: ANN001
    """``count`` stops by ``client`` while the page gets no telemetry (the tap drops it)."""
    driver.execute_script("window.hexactlTestTap.dropTelemetry = true")
    try:
        for _ in range(count):
            client.call("stop")
    finally:
        driver.execute_script("window.hexactlTestTap.dropTelemetry = false")


def test_after_a_restart_on_the_same_host_the_new_services_bursts_are_fetched_from_its_first_event(tmp_path) -> None:
    """Found from outside: the page took a new service only from the records' t going back,
    but t is the host's monotonic clock: after a restart on the same host the page kept the
    old service's last event number, took the new one's bursts for events it had, and
    listed only the eight each record carries. The numbers going back is a new service."""
    api, telemetry = f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}"
    driver = headless_chromium()
    try:
        driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": TAP})
        with dashboard(api, telemetry) as board:
            with serve(tmp_path, api=api, telemetry=telemetry) as first:
                driver.get(board.url)
                wait_for(lambda: driver.execute_script("return window.hexactlDashboard.dataLoss === null"),
                         "live data on the page")
                with HexactlClient(api, timeout_s=30.0, name=ANN) as ann:
                    for _ in range(100):
                        ann.call("stop")
                    old = ann.call("events", after=0)["events"]
                wait_for(lambda: listed(driver, old[-8:]), "the first service's events on the page")
                terminate(first)
            with serve(tmp_path, api=api, telemetry=telemetry):
                with HexactlClient(api, timeout_s=30.0, name=ANN) as ann:
                    now = ann.call("status")["status"]["t"]
                    wait_for(lambda: driver.execute_script(
                        "return window.hexactlDashboard.dataLoss === null && window.hexactlDashboard.record.t") >= now,
                        "the page live on the new service")
                    # a burst of 80 before the page sees any of the new service's events: more than it keeps (64)
                    stops_unseen(driver, ann, 80)
                    reply = ann.call("events", after=0)
                    kept, missed = reply["events"], reply["missed"]
                    assert kept[-1]["seq"] < old[-1]["seq"] and missed > 0, (kept[-1], old[-1], missed)
                    wait_for(lambda: listed(driver, kept), "every event the new service keeps on the page",
                             seen=lambda: [(e["code"], e["t"]) for e in page_events(driver)][:12])
                    said = f"{missed} events came and went before the page could ask"
                    wait_for(lambda: any(e["code"] == "events_missed" and e["message"].startswith(said)
                                         for e in page_events(driver)),
                             "the page saying how many it could not get", seen=lambda: page_events(driver)[-3:])
                    # then a burst after events the page has from the new service: fetched as a gap
                    last = kept[-1]["seq"]
                    stops_unseen(driver, ann, 20)
                    burst = ann.call("events", after=last)["events"]
                    assert len(burst) == 20, burst
                    wait_for(lambda: listed(driver, burst), "the second burst whole on the page",
                             seen=lambda: [(e["code"], e["t"]) for e in page_events(driver)][:12])
                    shown = page_events(driver)
                    keys = [(e["t"], e["code"], e["message"], e["sender"]) for e in shown]
                    assert len(keys) == len(set(keys)), shown
    finally:
        driver.quit()
