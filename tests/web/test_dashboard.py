"""``hexactl dashboard`` in a real headless Chromium (Debian's, driven by Selenium),
against a real ``hexactl serve`` on the simulator, each in a process of its own: what an
operator sees and does on the page, checked through the service's own API.

The bounds on waits only turn a hang into a failure: the service, the dashboard and a
software-rendering browser share a possibly busy two-core machine.
"""

from __future__ import annotations

import functools
import json
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.error import URLError
from urllib.request import urlopen

import numpy as np
import pytest
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.remote.webelement import WebElement
from selenium.webdriver.support.ui import Select

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.stream_client import PoseStream
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from tools.browser import dashboard, headless_chromium
from tests.reliability.support import enable, tolerating_stalls
from tools.serving import HANG_S, START_TIMEOUT_S, Logged, free_port, hexactl_process, serve, terminate, wait_until

ROOT = Path(__file__).resolve().parents[2]
SCREENSHOTS = ROOT / "docs" / "images"
WAIT_S = 60.0
wait_for = functools.partial(wait_until, timeout_s=WAIT_S)


def screenshot(driver, name: str, showing: str | None = None) -> None:  # noqa: ANN001
    """The view as the operator sees it, for docs/dashboard.md (where the checkout is
    writable), with the element ``showing`` (a CSS selector) scrolled into its panel's view."""
    if showing is not None:
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})",
                              driver.find_element(By.CSS_SELECTOR, showing))
    if os.access(SCREENSHOTS.parent, os.W_OK):
        SCREENSHOTS.mkdir(exist_ok=True)
        driver.save_screenshot(str(SCREENSHOTS / f"dashboard-{name}.png"))


class Rig:
    """The service, the dashboard, the browser on the page, and an API client to check."""

    def __init__(self, directory: Path, served, board, driver, client: HexactlClient) -> None:  # noqa: ANN001
        self.directory, self.served, self.board, self.driver, self.client = directory, served, board, driver, client

    def status(self) -> dict:
        """The service's status record; AssertionError at once if a fault latched (a wait
        for a motion then ends with its reason, and :meth:`scenario` judges it)."""
        record = self.client.call("status")["status"]
        assert record["state"] != "fault", f"fault latched: {record['faults']}"
        return record

    def scenario(self, body: Callable[[], None]) -> None:
        """``body``, again from the start if it failed while only a stall's faults were
        latched: the service, the dashboard and a software-rendering browser share a
        possibly busy host, whose stalls stop the simulated actuators by their watchdog.
        A fault of any other kind fails at once."""
        tolerating_stalls(self.client, body, self.at_rest_disabled)

    def element(self, selector: str):  # noqa: ANN201
        return self.driver.find_element(By.CSS_SELECTOR, selector)

    def shown(self, selector: str):  # noqa: ANN201
        """The element, its collapsed panel opened first as an operator would (its summary clicked)."""
        element = self.element(selector)
        panel = self.driver.execute_script("return arguments[0].closest('details')", element)
        if panel is not None and panel.get_attribute("open") is None:
            panel.find_element(By.TAG_NAME, "summary").click()
        return element

    def click(self, selector: str) -> None:
        self.shown(selector).click()

    def confirm(self, selector: str) -> None:
        """Press a button that asks for a second press (Play, Roll back, Clear all), then
        press it again once it asks."""
        self.click(selector)
        wait_for(lambda: "armed" in (self.element(selector).get_attribute("class") or ""), f"{selector} asking to confirm")
        time.sleep(0.45)  # a press sooner than 0.4 s after the question confirms nothing (controls.js)
        self.click(selector)

    def fill(self, selector: str, value: object) -> None:
        field = self.shown(selector)
        field.clear()
        field.send_keys(str(value))

    def page(self, script: str) -> object:
        return self.driver.execute_script(script)

    def connected(self) -> bool:
        return self.page("return document.body.dataset.connected") == "true"

    def severe_console_entries(self) -> list[dict]:
        return [entry for entry in self.driver.get_log("browser") if entry["level"] == "SEVERE"]

    def at_rest_disabled(self) -> None:
        """Whatever the previous test left: no fault, at rest, disabled."""
        record = self.client.call("status")["status"]
        if record["state"] in ("fault", "estop"):
            self.client.call("reset")
        elif record["state"] == "enabled":
            self.client.call("stop")
            wait_for(lambda: self.status()["motion"] == "holding", "the platform at rest")
            self.client.call("disable")
        wait_for(lambda: self.status()["state"] == "disabled", "disabled")

    def enabled_from_the_page(self) -> None:
        self.at_rest_disabled()
        self.click("#enable")
        wait_for(lambda: self.status()["state"] == "enabled", "enabled by the page's button")
        wait_for(lambda: self.element("#state").text.strip() == "enabled", "the page showing enabled")

    def jog_held(self, button: WebElement, jogging: Callable[[], bool], what: str) -> None:
        """``button`` pressed and held until ``jogging()``; pressed again, as an operator
        would, whenever the page refused the press and let the button go: on a busy host the
        jog that starts the hold can reach the service after its time to live, one deadman
        period (``expired``), or the page lose its live data for a moment."""
        def held_and_jogging() -> bool:
            if jogging():
                return True
            if "held" not in button.get_attribute("class").split():
                ActionChains(self.driver).release(button).click_and_hold(button).perform()
            return False

        ActionChains(self.driver).click_and_hold(button).perform()
        wait_for(held_and_jogging, what, seen=lambda: (self.element("#jog-status").text, self.status()))


@contextmanager
def page_on_a_service(directory: Path, before_load: str | None = None) -> Iterator[Rig]:
    """``hexactl serve`` in ``directory``, its dashboard, and the page open in headless
    Chromium, connected; ``before_load``: a script the page runs before its own."""
    with serve(directory) as served, dashboard(served.api, served.telemetry) as board:
        driver = headless_chromium()
        try:
            if before_load is not None:
                driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": before_load})
            with HexactlClient(served.api, timeout_s=30.0) as client:
                driver.get(board.url)
                rig = Rig(directory, served, board, driver, client)
                wait_for(rig.connected, "the page connected")
                yield rig
        finally:
            driver.quit()


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("dashboard")) as rig:
        wait_for(lambda: rig.page("return window.hexactlDashboard.geometry"), "the geometry on the page")
        yield rig


def drawn_and_commanded(rig: Rig) -> tuple[list[float], list[float]]:
    """The leg lengths the 3D view drew and the set-points of the record it drew (one read)."""
    lengths, setpoints = rig.page("const d = window.hexactlDashboard; return [d.legLengths(), d.record.leg_setpoints];")
    return lengths, setpoints


def test_the_page_loads_with_no_console_error_and_draws_the_services_setpoints(rig) -> None:
    def scenario() -> None:
        assert rig.severe_console_entries() == []
        reply = rig.client.call("geometry")
        geometry = reply["geometry"]
        assert rig.page("return window.hexactlDashboard.geometry.calibration_id") == reply["calibration_id"]
        rig.enabled_from_the_page()
        rig.client.call("move", pose=[40, -30, 60, 4, -3, 12], duration=1.0)  # legs of six different lengths
        wait_for(lambda: rig.status()["motion"] == "holding" and rig.status()["goal"] is None, "the move's end")
        time.sleep(0.5)  # a few telemetry records: the page draws the rest pose

        def same_record() -> tuple[list[float], list[float]] | None:
            lengths, setpoints = drawn_and_commanded(rig)
            return (lengths, setpoints) if setpoints == rig.status()["leg_setpoints"] else None

        lengths, setpoints = wait_for(same_record, "the page drawing the service's latest set-points")
        expected = np.asarray(geometry["zero_lengths"]) + (1 + np.asarray(geometry["sensor_scale_errors"])) * np.asarray(setpoints)
        assert len(set(np.round(lengths, 3))) == 6
        np.testing.assert_allclose(lengths, expected, atol=1e-6)
        screenshot(rig.driver, "overview")
        assert rig.severe_console_entries() == []

    rig.scenario(scenario)


def test_the_telemetry_poses_say_their_frame_and_units(rig) -> None:
    """The pose table said x … yaw and command, measured, goal: not in which units, nor
    that the first three are the platform's relative to the zero posture, as a move in
    the zero frame takes them, and the last the tool's in the work frame."""
    assert rig.shown("#pose-table caption").text == (
        "mm and °; command, measured, goal: the platform relative to the zero posture (frame zero); tool: its pose "
        "in the work frame")


def test_enable_then_a_validated_move_moves_the_simulated_platform(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        goal = [25.0, 10.0, 40.0, 0.0, 3.0, -5.0]
        for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), goal):
            rig.fill(f"#move-{axis}", value)
        assert not rig.element("#move-go").is_enabled()  # nothing to go to before a validation
        rig.click("#move-validate")
        wait_for(lambda: "valid" in rig.element("#move-result").get_attribute("class").split(), "the validation")
        screenshot(rig.driver, "move-validated", "#move-result")
        rig.click("#move-go")

        def arrived() -> bool:
            record = rig.status()
            measured = record["pose_measured"]
            return record["motion"] == "holding" and measured is not None and np.allclose(measured, goal, atol=0.05)

        wait_for(arrived, "the simulated platform at the goal (its measured pose)", seen=lambda: (
            rig.element("#move-result").text, rig.element("#messages").text[:500], rig.status()))

    rig.scenario(scenario)


def test_an_out_of_reach_goal_shows_its_refusal_and_moves_nothing(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        before = rig.status()["pose_command"]
        for axis, value in zip(("x", "y", "z", "roll", "pitch", "yaw"), (700, 0, 0, 0, 0, 0)):
            rig.fill(f"#move-{axis}", value)
        rig.click("#move-validate")
        result = rig.element("#move-result")
        wait_for(lambda: "refused" in result.get_attribute("class").split(), "the refusal")
        assert "path_violation: x 700 mm outside the pose envelope" in result.text, result.text
        assert "waypoint" not in result.text, result.text  # a single move is no sequence of waypoints
        assert not rig.element("#move-go").is_enabled()
        screenshot(rig.driver, "move-refused", "#move-result")
        time.sleep(0.5)
        record = rig.status()
        assert record["motion"] == "holding" and record["pose_command"] == before

    rig.scenario(scenario)


def test_jog_moves_while_held_and_brakes_when_released(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.fill("#jog-speed", 20)
        start_x = rig.status()["pose_command"][0]
        button = rig.element('.jog[data-axis="x"][data-direction="1"]')
        try:
            # Seen moving 5 mm out, not asked once: on a loaded host the page may renew late, the
            # deadman then brakes (as it must), and the page's next renewal jogs on.
            rig.jog_held(button, lambda: (record := rig.status())["pose_command"][0] > start_x + 5.0
                         and record["motion"] == "moving", "the platform jogging in +x while held")
        finally:
            ActionChains(rig.driver).release(button).perform()
        wait_for(lambda: rig.status()["motion"] == "holding", "the jog braked to rest after the release")
        rested = rig.status()["pose_command"]
        time.sleep(0.5)
        assert rig.status()["pose_command"] == rested  # at rest, not creeping on

    rig.scenario(scenario)


def test_escape_latches_the_estop_even_from_a_text_field(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        rig.element("#move-x").click()  # focus in a field: Escape must still stop
        ActionChains(rig.driver).send_keys(Keys.ESCAPE).perform()
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop latched by Escape")
        wait_for(lambda: rig.element("#state").text.strip() == "estop", "the page showing the E-stop")
        screenshot(rig.driver, "estop")
        rig.click("#reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset by the page's button")

    rig.scenario(scenario)


def test_a_calibration_load_shows_the_change_then_applies_it(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        nominal = load_geometry(ROOT / "config" / "platform.toml")
        calibrated = nominal.model_copy(update={"name": "dashboard test", "zero_lengths": tuple(
            length + 0.2 for length in nominal.zero_lengths)})
        (rig.directory / "calibrations" / "dashboard-test.toml").write_text(geometry_to_toml(calibrated))
        rig.click("#calibration-refresh")
        wait_for(lambda: any(option.get_attribute("value").endswith("dashboard-test.toml") for option in
                             Select(rig.element("#calibration-files")).options), "the file in the list")
        select = Select(rig.shown("#calibration-files"))
        select.select_by_value(next(option.get_attribute("value") for option in select.options
                                    if option.get_attribute("value").endswith("dashboard-test.toml")))
        assert not rig.element("#calibration-apply").is_enabled()  # not before the change is shown
        rig.click("#calibration-preview")
        change = rig.element("#calibration-change")
        wait_for(lambda: "valid" in change.get_attribute("class").split(), "the change shown")
        assert "0.200" in change.text and geometry_id(calibrated) in change.text, change.text
        assert rig.status()["calibration_id"] == geometry_id(nominal)  # shown, not applied
        screenshot(rig.driver, "calibration-preview", "#calibration-change")
        rig.click("#calibration-apply")
        wait_for(lambda: rig.status()["calibration_id"] == geometry_id(calibrated), "the calibration applied")
        wait_for(lambda: rig.page("return window.hexactlDashboard.geometry.calibration_id") == geometry_id(calibrated),
                 "the page drawing the new geometry")
        rig.client.call("rollback_calibration")
        wait_for(lambda: rig.status()["calibration_id"] == geometry_id(nominal), "rolled back")

    rig.scenario(scenario)


def test_killing_and_restarting_the_service_reconnects_the_page(tmp_path) -> None:
    api, telemetry = f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}"
    driver = headless_chromium()
    try:
        with dashboard(api, telemetry) as board:
            with serve(tmp_path, api=api, telemetry=telemetry) as served:
                driver.get(board.url)
                connected = lambda: driver.execute_script("return document.body.dataset.connected") == "true"  # noqa: E731
                wait_for(connected, "the page connected")
                served.process.send_signal(signal.SIGKILL)
                served.process.wait()
                wait_for(lambda: not connected(), "the page saying the service is gone")
                assert "disconnected" in driver.find_element(By.ID, "connection").text
            with serve(tmp_path, api=api, telemetry=telemetry):
                wait_for(connected, "the page reconnected to the restarted service")
                wait_for(lambda: driver.execute_script("return window.hexactlDashboard.record.state") == "disabled",
                         "fresh telemetry on the page")
                driver.find_element(By.ID, "enable").click()
                with HexactlClient(api, timeout_s=30.0) as client:
                    wait_for(lambda: client.call("status")["status"]["state"] == "enabled",
                             "a command from the reconnected page carried out")
    finally:
        driver.quit()


def test_a_narrow_window_still_shows_the_state_the_motion_the_estop_and_the_controller_buttons(rig) -> None:
    """Found from outside: in a window 683 px wide (half a laptop's screen) the E-STOP
    button covered the MOTION pill, and at 500 px the header clipped both pills away; at
    800×600 the stacked page scrolled Stop, Disable and Reset out of view."""
    def hidden() -> list[str]:  # the ones not shown whole, on top, inside the window
        return rig.page("""
            return ['state', 'motion', 'estop', 'enable', 'disable', 'stop', 'reset'].filter((id) => {
                const element = document.getElementById(id), r = element.getBoundingClientRect();
                const across = [0.15, 0.5, 0.85].map((f) => [r.left + f * r.width, (r.top + r.bottom) / 2]);
                return r.width === 0 || r.left < 0 || r.right > innerWidth || r.top < 0 || r.bottom > innerHeight
                    || !across.every(([x, y]) => element.contains(document.elementFromPoint(x, y)));
            });""")

    try:
        for width, height in ((683, 1000), (500, 1000), (800, 600)):
            rig.driver.set_window_size(width, height)
            wait_for(lambda: rig.page("return innerWidth") <= width, f"the window {width} px wide")
            for where in ("top", "bottom"):
                rig.page(f"window.scrollTo(0, {'0' if where == 'top' else 'document.body.scrollHeight'})")
                assert rig.page("return document.body.scrollHeight > innerHeight"), "a page that scrolls"
                assert hidden() == [], (width, height, where)
    finally:
        rig.page("window.scrollTo(0, 0)")
        rig.driver.set_window_size(1600, 1000)


def test_the_dashboard_refuses_another_sites_websocket_and_host(rig) -> None:
    from urllib.error import HTTPError
    from urllib.request import Request, urlopen

    with pytest.raises(HTTPError) as refused:
        urlopen(Request(rig.board.url, headers={"Host": "attacker.example"}), timeout=30)
    assert refused.value.code == 421
    opened = rig.page(f"""
        return await new Promise(done => {{
            const socket = new WebSocket("{rig.board.url.replace('http', 'ws')}ws");
            socket.onopen = () => done("open");
            socket.onclose = () => done("closed");
        }});""")
    assert opened == "open"  # the page's own origin is let in; another origin is the next check
    import asyncio

    import websockets

    async def from_elsewhere(origin: str) -> str:
        try:
            async with websockets.connect(rig.board.url.replace("http", "ws") + "ws", origin=origin):
                return "open"
        except websockets.InvalidStatus as error:
            return str(error.response.status_code)

    own = rig.board.url.split("://", 1)[1].rstrip("/")
    assert asyncio.run(from_elsewhere("http://attacker.example")) == "403"
    assert asyncio.run(from_elsewhere(f"evil://{own}")) == "403"  # this host and port, not a web page's scheme
    assert asyncio.run(from_elsewhere(f"http://{own}")) == "open"


@contextmanager
def another_site(html: str) -> Iterator[str]:
    """A web site of another origin (another port) serving ``html`` at its root: its URL."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
    from threading import Thread

    class Page(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            body = html.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    with ThreadingHTTPServer(("127.0.0.1", 0), Page) as server:
        Thread(target=server.serve_forever, daemon=True).start()
        try:
            yield f"http://127.0.0.1:{server.server_address[1]}/"
        finally:
            server.shutdown()


def test_another_site_cannot_show_the_page_in_a_frame(rig) -> None:
    """Another site open in the operator's browser showed the dashboard, live and connected,
    in a frame of its own page: under a decoy, the operator's clicks pressed its Enable, Go or
    jog buttons (clickjacking), its Host and Origin being the dashboard's own. Every response
    now forbids being framed; the page served as /static/index.html too."""
    from selenium.webdriver.common.by import By

    page = rig.driver.current_window_handle
    frame = f'<iframe id="decoy" src="{rig.board.url}" onload="window.frameLoaded = true"></iframe>'
    with another_site(frame) as url:
        rig.driver.switch_to.new_window("tab")
        try:
            rig.driver.get(url)
            wait_for(lambda: rig.page("return window.frameLoaded === true"), "the frame loaded (or refused)")
            rig.driver.switch_to.frame(rig.driver.find_element(By.ID, "decoy"))
            assert rig.driver.find_elements(By.CSS_SELECTOR, "#estop") == []
        finally:
            rig.driver.close()
            rig.driver.switch_to.window(page)
    for path in ("", "static/index.html"):
        with urlopen(f"{rig.board.url}{path}", timeout=30) as answer:
            assert answer.headers["X-Frame-Options"] == "DENY", path
            assert answer.headers["Content-Security-Policy"] == "frame-ancestors 'none'", path
            assert answer.headers["X-Content-Type-Options"] == "nosniff", path



def test_the_frames_panel_changes_only_the_soft_limits_filled_in(rig) -> None:
    """The panel sent only the soft-limit inputs filled in as soft_limits, which set_frames
    takes whole: a tilt bound typed alone removed the x, y, z bounds in force. An empty
    input now keeps what is in force, as an empty frame input does; null and none remove."""
    rig.at_rest_disabled()
    x, _, z = rig.status()["pose_command"][:3]  # wherever the tests before left the platform, inside the bounds
    lower, upper = [round(x) - 50, None, None, None, None, None], [round(x) + 50, None, round(z) + 60, None, None, None]
    rig.client.call("set_frames", soft_limits={"lower": lower, "upper": upper})

    def applied(expected: dict) -> bool:
        rig.click("#frames-apply")
        soft = lambda: rig.client.call("frames")["frames"]["soft_limits"]  # noqa: E731
        wait_for(lambda: soft() == expected, f"the service's soft limits {expected}",
                 seen=lambda: (soft(), rig.element("#frames-result").text))
        return True

    try:
        wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.soft_limits.lower[0]") == lower[0],
                 "the page told of the soft limits")
        for selector in ("#frame-work", "#frame-tool", "#soft-lower", "#soft-upper"):
            rig.fill(selector, "")
        rig.fill("#soft-max-tilt", "12")
        assert applied({"lower": lower, "upper": upper, "max_tilt_deg": 12})
        assert rig.element("#frames-result").text.startswith("frames set")
        wait_for(lambda: rig.page("return window.hexactlDashboard.record.frames.soft_limits.max_tilt_deg") == 12,
                 "the page told of the tilt bound")
        rig.fill("#soft-max-tilt", "none")
        rig.fill("#soft-upper", "null, null, null, null, null, 5")
        assert applied({"lower": lower, "upper": [None, None, None, None, None, 5], "max_tilt_deg": None})
        wait_for(lambda: rig.element("#frames-result").text.startswith("frames set"), "the page's result")
        # found from outside: once another client changed them, the result still showed the frames set here
        rig.client.call("set_frames", soft_limit_changes={"max_tilt_deg": 20})
        wait_for(lambda: rig.element("#frames-result").text.startswith("the frames in force have changed since "
                                                                        "this page set them"),
                 "the page's result withdrawn", seen=lambda: rig.element("#frames-result").text)
    finally:
        rig.client.call("clear_frames")


def test_a_recording_downloads_by_its_name_and_nothing_else_does(rig) -> None:
    """The page's download link: a recording as ``record`` named it, with ``.csv``; any other
    name is refused before the service is asked (the name rule is the API's, in one place)."""
    from urllib.error import HTTPError

    rig.client.call("record", name="board.download", duration_s=0.2, signals=["setpoints"])
    wait_for(lambda: rig.client.call("record_status")["state"] == "done", "the recording written")
    with urlopen(f"{rig.board.url}recordings/board.download.csv", timeout=30) as answer:
        assert answer.headers["Content-Disposition"] == 'attachment; filename="board.download.csv"'
        assert answer.read() == (rig.directory / "recordings" / "board.download.csv").read_bytes()
    for name in ("board.download.json", ".hidden.csv", "-rf.csv", "x" * 101 + ".csv", "a%20b.csv"):
        with pytest.raises(HTTPError) as refused:
            urlopen(f"{rig.board.url}recordings/{name}", timeout=30)
        assert refused.value.code == 400, name
        assert refused.value.read().decode().endswith(": not a recording's name (NAME.csv, as given to record)")


def test_pages_are_sent_one_uncompressed_text_per_record(rig) -> None:
    """The cost of a record is one serialisation for all pages (found from outside: 400
    idle pages held a new page's E-stop back 0.6–0.9 s while the dashboard serialised and
    compressed each record once per page): two pages that offer permessage-deflate, as
    browsers do, are sent the same text for the same record, uncompressed."""
    from websockets.sync.client import connect

    url = rig.board.url.replace("http", "ws") + "ws"
    with connect(url, open_timeout=WAIT_S) as first, connect(url, open_timeout=WAIT_S) as second:
        assert "permessage-deflate" in first.request.headers["Sec-WebSocket-Extensions"]
        assert all(page.response.headers.get("Sec-WebSocket-Extensions") is None for page in (first, second))
        seen: tuple[dict, dict] = ({}, {})
        deadline = time.monotonic() + WAIT_S  # bounds a hang only
        while not seen[0].keys() & seen[1].keys():
            assert time.monotonic() < deadline, "no record sent to both pages"
            for page, texts in zip((first, second), seen):
                message = page.recv(WAIT_S)
                parsed = json.loads(message)
                if parsed["type"] == "telemetry":
                    texts[parsed["record"]["t"]] = message
        t = min(seen[0].keys() & seen[1].keys())
        assert seen[0][t] == seen[1][t]


def dashboard_connected(port: int) -> bool:
    """Whether the dashboard on ``port`` answers and is connected to its service."""
    try:
        with urlopen(f"http://127.0.0.1:{port}/health", timeout=5) as answer:
            return json.load(answer)["connected"]
    except (URLError, OSError):
        return False


def dashboard_children(pid: int) -> list[int]:
    """The dashboard processes among ``pid``'s descendants (``hexactl demo`` runs its
    service in a process of its own)."""
    found = []
    try:
        children = [int(child) for task in Path(f"/proc/{pid}/task").iterdir()
                    for child in (task / "children").read_text().split()]
    except OSError:  # ended meanwhile
        return found
    for child in children:
        try:
            if b"dashboard" in Path(f"/proc/{child}/cmdline").read_bytes():
                found.append(child)
                continue
        except OSError:
            continue
        found.extend(dashboard_children(child))
    return found


def ended(pid: int) -> bool:
    """No such process, or only its zombie."""
    return not Path(f"/proc/{pid}").exists() or Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"


def test_serve_with_dashboard_serves_the_page_beside_it_and_stops_it_with_it(tmp_path) -> None:
    port = free_port()
    with serve(tmp_path, "--dashboard", f"127.0.0.1:{port}") as served:
        wait_for(lambda: dashboard_connected(port), "the dashboard serving, connected to its service")
        shutdown = terminate(served)
        assert shutdown.problems() == [], served.log
    with pytest.raises((URLError, OSError)):
        urlopen(f"http://127.0.0.1:{port}/health", timeout=5)


def killed_and_started_again(running: Logged, port: int) -> int:
    """Kill the dashboard that ``running`` serves on ``port``, once it is connected; the
    pid of the one started again, once ``running``'s log said so and it serves there."""
    wait_for(lambda: dashboard_connected(port), "the dashboard serving, connected to its service",
             seen=lambda: running.log)
    [first] = dashboard_children(running.process.pid)
    os.kill(first, signal.SIGKILL)
    wait_for(lambda: "the dashboard's process ended (killed by SIGKILL)" in running.log, "the log to say so",
             seen=lambda: running.log)
    [second] = wait_for(lambda: [pid for pid in dashboard_children(running.process.pid) if pid != first],
                        "a new dashboard process", seen=lambda: running.log)
    wait_for(lambda: dashboard_connected(port), "the new dashboard serving on the same address",
             seen=lambda: running.log)
    return second


def test_a_dashboard_that_dies_is_said_and_started_again(tmp_path) -> None:
    """The pages of a dead dashboard show that they have no live data (test_data_loss.py);
    the service says so on its log and starts it again on the same address."""
    port = free_port()
    with serve(tmp_path, "--dashboard", f"127.0.0.1:{port}") as served:
        second = killed_and_started_again(served, port)
        assert served.log.count("dashboard starting on http://127.0.0.1:") == 2, served.log
        shutdown = terminate(served)
        assert shutdown.problems() == [], served.log
    assert ended(second)


def test_the_demo_starts_its_dashboard_again_too(tmp_path) -> None:
    """``hexactl demo --dashboard``'s main thread runs the campaign: the dashboard's own
    watcher starts it again all the same."""
    port = free_port()
    with hexactl_process(Logged, ["demo", "--dashboard", f"127.0.0.1:{port}"], re.compile(r"dashboard on http://"),
                         START_TIMEOUT_S, cwd=tmp_path, merge_stdout=True, sigterm_grace_s=HANG_S) as demo:
        second = killed_and_started_again(demo, port)
        demo.process.send_signal(signal.SIGINT)
        demo.process.wait(HANG_S)
    wait_for(lambda: ended(second), "the dashboard ended with the demo")


def test_the_dashboard_of_a_killed_service_ends_by_itself(tmp_path) -> None:
    with serve(tmp_path, "--dashboard", f"127.0.0.1:{free_port()}") as served:
        [pid] = wait_for(lambda: dashboard_children(served.process.pid), "the dashboard's process")
        served.process.kill()
        served.process.wait()
        wait_for(lambda: ended(pid), "the dashboard ended")


def test_a_campaigns_progress_and_its_finished_report_show_in_the_page(rig) -> None:
    """What ``hexactl campaign`` tells the service (``progress``), as the page renders it."""
    rig.client.call("progress", title="postures", done=7, total=18, label="leg 3 locked", said="measuring with the simulator")
    rig.shown("#campaign-progress")
    wait_for(lambda: "postures 7/18 · leg 3 locked" in rig.element("#campaign-progress").text, "the progress shown")
    assert "measuring with the simulator" in rig.element("#campaign-said").text
    report = {"method": "full", "calibration_id": "0123456789abcdef", "postures": 18, "residual_rms_mm": 0.21,
              "expected_rms_mm": 0.2, "fit": "χ²/dof 1.050", "improved": True, "warnings": ["weakly determined: zero6"],
              "parameters": [{"name": "B1.x", "value": 612.3456, "sigma": 0.0213},
                             {"name": "zero6", "value": 1750.5, "sigma": None},
                             {"name": "scale2", "value": 4.2e-4, "sigma": 1.1e-5}],
              "validation": [{"motion": "x_sweep", "before_position_mm": 31.2, "before_orientation_deg": 0.52,
                              "after_position_mm": 0.14, "after_orientation_deg": 0.003}]}
    rig.client.call("progress", title="identification", done=1, total=1, said="largest error: 31.200 mm → 0.140 mm",
                    report=report)
    box = rig.element("#campaign-report")
    wait_for(lambda: box.is_displayed() and "0123456789abcdef" in box.text, "the report shown")
    assert "improved" in box.text and "31.200" in box.text and "0.140" in box.text and "zero6" in box.text
    box.find_element(By.TAG_NAME, "summary").click()  # the parameters with their σ
    wait_for(lambda: "0.0213" in box.text and "undetermined" in box.text and "420.0" in box.text, "the parameters")
    screenshot(rig.driver, "campaign", "#campaign-report")


def test_a_pose_stream_shows_while_it_runs_and_how_it_ended(rig) -> None:
    summary = rig.shown("#stream-summary")

    def body() -> None:
        rig.at_rest_disabled()
        enable(rig.client)  # resets an actuator its watchdog stopped while disabled (a busy host), as an operator would
        wait_for(lambda: rig.status()["motion"] == "holding", "enabled at rest")
        with PoseStream(rig.client, "page test", timeout_ms=2000) as stream:
            number = stream.opened["stream"]
            # Fed by a thread of its own: sent between the page's reads, a busy host's slow read
            # (seconds) let the stream time out, and the page rightly showed it ended.
            fed = threading.Event()

            def feed() -> None:
                while not fed.wait(0.02):
                    stream.send((0.5, 0, 0, 0, 0, 0))

            feeder = threading.Thread(target=feed, name="stream-feeder", daemon=True)
            feeder.start()
            try:
                wait_for(lambda: f"stream {number} from page test (zero) following" in (text := summary.text)
                         and "clamped 0" in text, "the stream on the page", seen=lambda: summary.text)
            finally:
                fed.set()
                feeder.join()
        wait_for(lambda: summary.text.startswith(f"last stream {number}: "), "how it ended", seen=lambda: summary.text)
        assert "closed by the client" in summary.text, summary.text
        rig.client.call("disable")

    rig.scenario(body)
