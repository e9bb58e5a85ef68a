"""What the dashboard shows when its data are lost, in a real headless Chromium against a
real ``hexactl serve``: the service killed, the dashboard server gone, an E-stop pressed
meanwhile (found from outside: the page went on showing STATE enabled, MOTION moving and
``goal … in 4.5 s`` after the service died, and warned of an unconfirmed E-stop only 5 s
after the press).

The page is judged by what it shows and by the order of its own E-stop events
(``window.hexactlDashboard.estopEvents()``), never by how long anything took: the waits'
bounds only turn a hang into a failure on a busy two-core host.
"""

from __future__ import annotations

import functools
import json
import re
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.error import URLError
from urllib.request import urlopen

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys

from hexactl.adapters.api.client import HexactlClient
from tests.reliability.support import enable
from tools.browser import dashboard, headless_chromium
from tools.serving import Served, free_port, serve, wait_until

WAIT_S = 60.0
wait_for = functools.partial(wait_until, timeout_s=WAIT_S)


GREEN_BACKGROUND = "rgb(20, 83, 45)"  # .pill.st-enabled
MARGIN_GREEN = "rgb(134, 239, 172)"  # td.m-ok

SHOWN = """
const $ = (id) => document.getElementById(id);
const css = (el, p) => getComputedStyle(el).getPropertyValue(p);
const margin = document.querySelector('#leg-table tbody tr:nth-child(3) td');
return {
  loss: window.hexactlDashboard.dataLoss,
  live: document.body.dataset.live,
  stale: document.body.classList.contains('stale'),
  state: $('state').textContent, state_class: $('state').className, state_background: css($('state'), 'background-color'),
  motion: $('motion').textContent, motion_class: $('motion').className,
  age: $('data-age').textContent, age_shown: $('data-age').checkVisibility(),
  banner_shown: $('data-lost').checkVisibility(), banner: $('data-lost').innerText,
  hud: $('view3d-hud').textContent, loop: $('loop-summary').textContent,
  margin: margin.textContent, margin_color: css(margin, 'color'),
  canvas_filter: css(document.querySelector('#view3d canvas') ?? document.body, 'filter'),
  warning_shown: $('estop-warning').checkVisibility(), warning: $('estop-warning').innerText,
  dismiss_enabled: !$('estop-warning-dismiss').disabled,
};"""


def shown(driver) -> dict:  # noqa: ANN001 - selenium's driver
    """What the page shows, read in one script."""
    return driver.execute_script(SHOWN)


def page_when(driver, condition: Callable[[dict], bool], what: str) -> dict:  # noqa: ANN001
    """What the page shows, once ``condition`` holds for it."""
    def met() -> dict | None:
        page = shown(driver)
        return page if condition(page) else None

    return wait_for(met, what, seen=lambda: shown(driver))


def estop_events(driver, press: int | None = None) -> list[dict]:  # noqa: ANN001
    """The page's E-stop events, in order (those of one press when given)."""
    events = driver.execute_script("return window.hexactlDashboard.estopEvents()")
    return [event for event in events if press is None or event["press"] == press]


def press_escape(driver) -> int:  # noqa: ANN001
    """Escape pressed in a text field (as an operator typing would); the press's number."""
    before = driver.execute_script("return window.hexactlDashboard.estopEvents().filter(e => e.what === 'pressed').length")
    driver.find_element(By.ID, "move-x").click()
    ActionChains(driver).send_keys(Keys.ESCAPE).perform()
    presses = wait_for(lambda: [e["press"] for e in estop_events(driver) if e["what"] == "pressed"][before:],
                       "the page taking the press")
    return presses[-1]


def live(driver) -> bool:  # noqa: ANN001
    return driver.execute_script("return window.hexactlDashboard.dataLoss === null")


def showing_enabled_and_moving(driver, client: HexactlClient) -> dict:  # noqa: ANN001
    """Enable and start a long move, until the page shows enabled and moving; again from a
    reset if a busy host's stall latched a fault meanwhile."""
    def attempt() -> dict | None:
        record = client.call("status")["status"]
        if record["state"] in ("fault", "estop"):
            client.call("reset")
            return None
        if record["state"] != "enabled":
            enable(client)
            return None
        if record["motion"] == "holding":
            goal = -40.0 if record["pose_command"][0] > -20.0 else 40.0
            client.call("move", pose=[goal, 0, 0, 0, 0, 0], duration=30.0)
            return None
        page = shown(driver)
        return page if page["state"] == "enabled" and page["motion"] == "moving" and page["loss"] is None else None

    page = wait_until(attempt, "the page showing enabled and moving", timeout_s=3 * WAIT_S, poll_s=0.2,
                      seen=lambda: shown(driver))
    assert "goal" in page["hud"] and " in " in page["hud"], page  # the time to go, shown while live
    assert page["state_background"] == GREEN_BACKGROUND and not page["stale"] and not page["banner_shown"], page
    return page


def assert_no_live_data_shown(page: dict, lost: str, age: str = r"no data for \d+ s") -> None:
    """Nothing shown as current: UNKNOWN in grey, the ``age``, the banner naming what was lost
    and the hardware E-stop, the overlay's goal and time to go gone, the rest greyed."""
    assert page["state"] == "UNKNOWN" and page["motion"] == "UNKNOWN", page
    assert "pill-unknown" in page["state_class"] and "st-enabled" not in page["state_class"], page
    assert "mo-moving" not in page["motion_class"], page
    assert page["state_background"] != GREEN_BACKGROUND, page
    assert page["age_shown"] and re.fullmatch(age, page["age"]), page
    assert page["banner_shown"] and "NO LIVE DATA" in page["banner"] and "HARDWARE E-STOP" in page["banner"], page
    assert lost in page["banner"], page
    assert page["hud"].startswith("NO LIVE DATA") and " in " not in page["hud"].split("\n", 1)[1], page
    assert "enabled" not in page["hud"] and "moving" not in page["hud"], page
    assert page["loop"] == "no data", page
    assert page["stale"] and page["live"] == "false", page
    assert page["margin_color"] != MARGIN_GREEN, page  # the stroke margins greyed
    assert "grayscale" in page["canvas_filter"], page  # the 3D view greyed


def age_seconds(page: dict) -> int:
    return int(re.fullmatch(r"no data for (\d+) s", page["age"])[1])


def counting_up(driver, page: dict) -> None:  # noqa: ANN001
    """The age of the data counts up, while nothing else changes."""
    first = age_seconds(page)
    later = page_when(driver, lambda p: p["age"] and age_seconds(p) > first, "the age counting up")
    assert later["state"] == "UNKNOWN" and later["banner_shown"], later


@contextmanager
def page_of_a_dashboard() -> Iterator[tuple[Any, Any, str, str]]:
    """A headless page, and a dashboard of its own (``hexactl dashboard``) for a service on
    free API and telemetry ports: (driver, dashboard, api, telemetry)."""
    api, telemetry = f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}"
    driver = headless_chromium()
    try:
        with dashboard(api, telemetry) as board:
            yield driver, board, api, telemetry
    finally:
        driver.quit()


@contextmanager
def service_shown(tmp_path: Path, driver, board, api: str, telemetry: str  # noqa: ANN001
                  ) -> Iterator[tuple[Served, HexactlClient]]:
    """A service on ``api`` and ``telemetry``, its client, and the page showing its live data."""
    with serve(tmp_path, api=api, telemetry=telemetry) as served, HexactlClient(api, timeout_s=30.0) as client:
        driver.get(board.url)
        wait_for(lambda: live(driver), "live data on the page", seen=lambda: shown(driver))
        yield served, client


def test_a_killed_service_shows_state_unknown_and_the_banner_until_telemetry_returns(tmp_path) -> None:
    with page_of_a_dashboard() as (driver, board, api, telemetry):
        with service_shown(tmp_path, driver, board, api, telemetry) as (served, client):
            showing_enabled_and_moving(driver, client)
            served.process.send_signal(signal.SIGKILL)
            served.process.wait()
            page_when(driver, lambda p: p["state"] == "UNKNOWN", "the page saying the state is unknown")
            page = page_when(driver, lambda p: p["banner_shown"], "the banner")
            assert page["loss"] in ("service", "telemetry"), page  # the dashboard server still answers
            assert_no_live_data_shown(page, "hexactl service")
            assert "lost the dashboard server" not in page["banner"], page  # the service, not the server
            counting_up(driver, page)
        with serve(tmp_path, api=api, telemetry=telemetry):
            page = page_when(driver, lambda p: p["loss"] is None and p["state"] == "disabled",
                             "live data again: the restarted service's state")
            assert not page["banner_shown"] and not page["stale"] and not page["age_shown"], page
            assert "pill-unknown" not in page["state_class"] and page["loop"] != "no data", page
            assert not page["hud"].startswith("NO LIVE DATA"), page


def test_a_stopped_control_loop_shows_state_unknown_though_telemetry_still_comes(tmp_path) -> None:
    """The loop's process stopped (SIGSTOP; hung alike) while the API's runs on: telemetry
    kept coming, every record the loop's last report, and the page showed it as current,
    moving. Now the record says how old the report is, and past a second the page shows
    nothing as current, naming the loop, until the loop reports again. An E-stop pressed
    meanwhile is answered at once, queued for the loop (``loop_silent``): the page warns
    it is not confirmed."""
    with page_of_a_dashboard() as (driver, board, api, telemetry):
        with service_shown(tmp_path, driver, board, api, telemetry) as (served, client):
            showing_enabled_and_moving(driver, client)
            served.process.send_signal(signal.SIGSTOP)  # the loop's process; the API's is its child
            try:
                page = page_when(driver, lambda p: p["loss"] == "loop" and p["banner_shown"], "the banner")
                assert_no_live_data_shown(page, "control loop has sent nothing", age=r"no loop report for \d+ s")
                press = press_escape(driver)
                replied = wait_for(lambda: [e for e in estop_events(driver, press) if e["what"].startswith("reply")],
                                   "the E-stop's reply", seen=lambda: estop_events(driver, press))
                assert [(e["what"], e["detail"]) for e in replied] == [("reply-failed", "loop_silent")], replied
                page = shown(driver)
                assert page["warning_shown"] and "queued, to be carried out if the loop runs again" in page["warning"], page
            finally:
                served.process.send_signal(signal.SIGCONT)
            page = page_when(driver, lambda p: p["loss"] is None and p["state"] != "UNKNOWN",
                             "live data again once the loop reports")
            assert not page["banner_shown"] and not page["stale"] and not page["age_shown"], page


def test_the_dashboard_server_gone_shows_state_unknown_the_banner_and_an_estop_not_sent(tmp_path) -> None:
    """The tester's case: ``serve --dashboard``, a move, SIGTERM to the service (which stops
    its dashboard too); then Escape, which cannot be sent at all."""
    port = free_port()
    url = f"http://127.0.0.1:{port}/"

    def board_connected() -> bool:
        try:
            with urlopen(f"{url}health", timeout=5) as answer:
                return json.load(answer)["connected"]
        except (URLError, OSError):
            return False

    driver = headless_chromium()
    try:
        with serve(tmp_path, "--dashboard", f"127.0.0.1:{port}") as served, \
                HexactlClient(served.api, timeout_s=30.0) as client:
            wait_for(board_connected, "the dashboard serving, connected to its service")
            driver.get(url)
            wait_for(lambda: live(driver), "live data on the page", seen=lambda: shown(driver))
            showing_enabled_and_moving(driver, client)
            served.process.send_signal(signal.SIGTERM)
            served.process.wait(WAIT_S)
            page = page_when(driver, lambda p: p["loss"] == "server" and p["banner_shown"],
                             "the page saying the dashboard server is lost")
            assert_no_live_data_shown(page, "dashboard server")
            counting_up(driver, page)

            press = press_escape(driver)
            page = shown(driver)
            assert page["warning_shown"] and "E-STOP NOT CONFIRMED" in page["warning"], page
            assert "use the hardware E-stop" in page["warning"] and "NOT SENT" in page["warning"], page
            assert [event["what"] for event in estop_events(driver, press)] == ["pressed", "warning"]
            assert not page["dismiss_enabled"], page  # nothing live to dismiss it against
    finally:
        driver.quit()


def test_escape_with_stale_telemetry_warns_not_confirmed_before_any_reply(tmp_path) -> None:
    with page_of_a_dashboard() as (driver, board, api, telemetry):
        with service_shown(tmp_path, driver, board, api, telemetry) as (served, client):
            enable(client)

            # live data: the service answers, and the page shows no warning (as before)
            def pressed_while_live() -> list[dict] | None:
                press = press_escape(driver)
                wait_for(lambda: any(e["what"].startswith("reply") for e in estop_events(driver, press)),
                         "the E-stop's reply", seen=lambda: estop_events(driver, press))
                events = estop_events(driver, press)
                return events if events[0]["detail"] == "live" else None  # a busy host's stall: again

            events = wait_for(pressed_while_live, "an E-stop pressed while the page had live data")
            assert [e["what"] for e in events][:3] == ["pressed", "sent", "reply-ok"], events
            assert "warning" not in [e["what"] for e in events], events
            assert client.call("status")["status"]["state"] == "estop"
            assert not shown(driver)["warning_shown"]
            client.call("reset")

            served.process.send_signal(signal.SIGKILL)
            served.process.wait()
            wait_for(lambda: shown(driver)["stale"], "the page showing stale telemetry", seen=lambda: shown(driver))
            assert driver.execute_script("return window.hexactlDashboard.connected") is False

            press = press_escape(driver)
            page, events = shown(driver), estop_events(driver, press)
            # sent (the socket is open: the service might only have lost its telemetry), and
            # warned at once: before any reply, whenever that reply comes
            assert [e["what"] for e in events][:3] == ["pressed", "sent", "warning"], events
            assert page["warning_shown"] and "E-STOP NOT CONFIRMED — use the hardware E-stop" in page["warning"], page
            assert not page["dismiss_enabled"], page

            failed = wait_for(lambda: [e for e in estop_events(driver, press) if e["what"].startswith("reply")],
                              "the dashboard's answer for the dead service", seen=lambda: estop_events(driver, press))
            assert failed[0]["what"] == "reply-failed", failed
            page = shown(driver)
            assert page["warning_shown"] and "E-STOP NOT CONFIRMED" in page["warning"], page  # a failure confirms nothing

        with serve(tmp_path, api=api, telemetry=telemetry):
            wait_for(lambda: live(driver), "live data again", seen=lambda: shown(driver))
            page = shown(driver)
            assert page["warning_shown"] and page["dismiss_enabled"], page  # stays until confirmed or dismissed
            press = press_escape(driver)
            wait_for(lambda: not shown(driver)["warning_shown"], "the warning cleared by a confirmed E-stop",
                     seen=lambda: estop_events(driver, press))
            assert [e["what"] for e in estop_events(driver, press)][-2:] == ["reply-ok", "cleared"]
