"""``hexactl monitor`` without a terminal emulator: the view's text and units, what each key
sends, single keys from a pseudo-terminal (a bare Escape told from an arrow key's
sequence), and the plain outputs (``--once``, ``--json`` into a pipe that closes early).
Through a real terminal: tests/cli/test_monitor_tmux.py."""

from __future__ import annotations

import io
import re
import json
import os
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from rich.console import Console

from hexactl.adapters.api.client import ServiceUnavailable
from hexactl.adapters.cli.main import main
from hexactl.adapters.cli.monitor import (
    ESCAPE,
    KEY_COMMANDS,
    LEGEND,
    KeyReader,
    KeyThread,
    ServiceCheck,
    key_result,
    say_if_moving,
    view,
)
from tests.api.support import start_service
from tools.serving import unserved_endpoint

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 60.0  # only turns a hang into a failure

RECORD: dict[str, Any] = {
    "t": 12.5, "state": "enabled", "motion": "moving",
    "pose_command": [1.0, 2.0, 3.0, 0.5, -0.25, 5.0], "pose_measured": [1.001, 2.0, 3.0, 0.5, -0.25, 5.0],
    "goal": [0.0, 0.0, 50.0, 0.0, 0.0, 5.0], "remaining_s": 1.234,
    "leg_setpoints": [425.0, 426.0, 427.0, 428.0, 429.0, 430.0], "leg_feedback": [425.1, None, 427.1, 428.1, 429.1, 430.1],
    "locked_leg": 3, "calibration_id": "0fd49f5a13b75edc",
    "sequence": {"name": "x_sweep", "index": 2, "total": 5, "phase": "dwelling"},
    "faults": [{"code": "actuator_fault", "message": "overcurrent", "leg": 4}],
    "loop": {"rate_hz": 500.0, "cycles": 1000, "missed": 3, "skipped": 0,
             "lateness_us": {"p50": 41, "p99": 120, "p999": 300, "max": 900},
             "compute_us": {"p50": 80, "p99": 150, "p999": 200, "max": 400}},
    "realtime": None,
}


def rendered(record: dict[str, Any] | None, status: str = "", waiting: str | None = None) -> str:
    console = Console(file=io.StringIO(), width=120, record=True)
    console.print(view(record, status, waiting))
    return console.export_text()


def test_the_view_shows_every_value_with_its_unit() -> None:
    text = rendered(RECORD, "stop: ok: stopping")
    for expected in ("ENABLED", "moving", "remaining 1.23 s",
                     "x mm", "y mm", "z mm", "roll deg", "pitch deg", "yaw deg", "50.000", "-0.250",
                     "L1 mm", "L3 mm locked", "426.000", "430.100",
                     "0fd49f5a13b75edc", "x_sweep 2/5 (dwelling)", "leg 4: actuator_fault (overcurrent)",
                     "500 Hz, 1000 cycles, 3 missed", "lateness µs", "p99 120", "compute µs",
                     LEGEND, "stop: ok: stopping"):
        assert expected in text, expected
    rows = {line.split()[0]: line.split()[1:] for line in text.splitlines() if line.split()}
    assert rows["goal"] == ["0.000", "0.000", "50.000", "0.000", "0.000", "5.000"]
    assert rows["feedback"][1] == "—"  # leg 2 not heard from


def test_the_view_names_a_legs_fault_bits_beside_the_word() -> None:
    healthy = {"state": "enabled", "fault_bits": 0, "fault_names": [], "report_age_s": 0.001}
    faulted = {"state": "fault", "fault_bits": 0x81, "fault_names": ["comm_timeout", "sensor"], "report_age_s": 0.001}
    *_, legs_row = (line for line in rendered({**RECORD, "legs": [healthy] * 4 + [faulted, healthy]}).splitlines()
                    if line.startswith("legs "))  # the last: the first heads the table of lengths
    assert legs_row.split() == ["legs", "L1", "enabled", "L2", "enabled", "L3", "enabled", "L4", "enabled",
                                "L5", "fault:", "comm_timeout,", "sensor", "(0x81)", "L6", "enabled"]
    estop = {"state": "estop", "fault_bits": 0x2, "fault_names": ["estop"], "report_age_s": 0.001}
    assert "legs         all estop: estop (0x2)" in rendered({**RECORD, "legs": [estop] * 6})


def test_a_long_fault_keeps_to_one_line_and_status_prints_it_whole_with_the_last_event() -> None:
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    sender = "hexactl operator@hexapod-controller-01.beamline.example.org (10.20.30.40, key operator)"
    estop = {**RECORD, "state": "estop", "faults": [{"code": "estop", "message": f"estop command from {sender}"}],
             "events": [{"t": RECORD["t"] - 2.5, "code": "estop", "message": "estop command", "sender": sender}]}
    text = rendered(estop, "estop: ok")
    [faults] = [line for line in text.splitlines() if line.startswith("faults")]
    assert faults.startswith("faults       estop (estop command from hexactl operator@") and faults.endswith("…")
    assert "estop: ok" in text.splitlines()[1]  # the key's result, under the legend whatever the record holds
    [last] = [line for line in text.splitlines() if line.startswith("last event")]
    assert last.startswith("last event   estop: estop command, sent by hexactl operator@") and last.endswith("…")
    printed = format_telemetry(estop)
    assert f"estop (estop command from {sender})" in printed
    assert f"last event     estop: estop command, sent by {sender} (2.5 s ago)" in printed
    assert "last event     none" in format_telemetry(RECORD)


def test_the_view_shows_the_frames_the_tool_pose_and_the_soft_limits() -> None:
    assert "frames" in rendered(RECORD) and "none (poses relative to the zero posture)" in rendered(RECORD)
    framed = {**RECORD, "tool_pose_command": [0.0, 0.0, 0.0, 5.0, 0.0, 0.0],
              "frames": {"work": [0.0, 0.0, 300.0, 0.0, 0.0, 0.0], "tool": [0.0, 0.0, 300.0, 0.0, 0.0, 0.0],
                         "soft_limits": {"lower": [-50.0, None, None, None, None, None],
                                         "upper": [50.0, None, None, None, None, None], "max_tilt_deg": 12.0}}}
    text = rendered(framed)
    assert "tool frame   x    0.000 mm  y    0.000 mm  z  300.000 mm" in text
    assert "soft limits  x -50..50 mm, tilt ≤ 12 deg" in text
    assert "tool in work  0.000" in text and "5.000" in text


def test_the_view_and_status_show_the_jog_and_the_recording() -> None:
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    assert "jog          none" in rendered(RECORD) and "recording    none" in rendered(RECORD)
    busy = {**RECORD, "jog": {"jog": 17, "frame": "tool", "velocity": [0.0, 0.0, 0.0, 2.0, 0.0, 0.0], "speed": 1.0,
                              "phase": "jogging", "end": "the soft tilt limit at 12 deg", "to_limit": True,
                              "renew_within_s": 0.15},
            "recording": {"state": "recording", "name": "run2", "rows": 1200, "rows_requested": 2500, "lost": 0,
                          "ended": None}}
    jog = "jog 17 jogging roll 2 deg/s in tool, to the soft tilt limit at 12 deg (renew within 0.15 s)"
    for text in (rendered(busy), format_telemetry(busy)):
        assert jog in text and "run2 recording 1200/2500 rows" in text


def test_the_view_at_rest_and_before_any_telemetry() -> None:
    text = rendered({**RECORD, "motion": "holding", "goal": None, "remaining_s": None, "sequence": None, "faults": []})
    assert "remaining at rest" in text
    assert [line.split()[1:] for line in text.splitlines() if line.startswith("goal")] == [["—"] * 6]
    waiting = rendered(None, "", "no telemetry from tcp://127.0.0.1:1 for 6 s: is `hexactl serve` running there?")
    assert "waiting for telemetry" in waiting and "no telemetry from tcp://127.0.0.1:1" in waiting


class RecordingClient:
    def __init__(self, reply: dict[str, Any] | Exception) -> None:
        self.reply = reply
        self.sent: list[str] = []

    def request(self, cmd: str, **fields: Any) -> dict[str, Any]:
        self.sent.append(cmd)
        if isinstance(self.reply, Exception):
            raise self.reply
        return self.reply


@pytest.mark.parametrize(("key", "command"), [
    (" ", "stop"), (ESCAPE, "estop"), ("e", "estop"), ("p", "pause"), ("r", "resume"), ("x", "reset"),
])
def test_each_key_sends_its_command_and_says_the_reply(key: str, command: str) -> None:
    assert KEY_COMMANDS[key] == command
    client = RecordingClient({"ok": True, "message": "done"})
    assert key_result(key, client, ServiceUnavailable) == f"{command}: ok: done"
    assert client.sent == [command]


def test_a_refusal_an_unknown_key_and_no_answer_are_said() -> None:
    refused = RecordingClient({"ok": False, "error": {"code": "latched", "message": "estop is latched: reset first"}})
    assert key_result("p", refused, ServiceUnavailable) == "pause: error latched: estop is latched: reset first"
    unknown = RecordingClient({"ok": True})
    assert key_result("\x1b[A", unknown, ServiceUnavailable).startswith("'\\x1b[A': not a key of the monitor")
    assert unknown.sent == []
    silent = RecordingClient(ServiceUnavailable("no answer from tcp://x within 5 s"))
    assert key_result(" ", silent, ServiceUnavailable) == "stop: no answer from tcp://x within 5 s"


def test_an_estop_key_not_answered_ok_says_it_is_not_confirmed() -> None:
    """A stopped loop's service answers an E-stop ``loop_silent`` (queued, not latched):
    the status line said only that, not to reach for the hardware E-stop, as ``hexactl
    estop`` and the dashboard do."""
    queued = RecordingClient({"ok": False, "error": {"code": "loop_silent", "message": "queued, to be carried out "
                                                     "if the loop runs again"}})
    assert key_result("e", queued, ServiceUnavailable) == ("estop: error loop_silent: queued, to be carried out if the "
                                                           "loop runs again; E-STOP NOT CONFIRMED: use the hardware E-stop")
    silent = RecordingClient(ServiceUnavailable("no answer from tcp://x within 5 s"))
    assert key_result(ESCAPE, silent, ServiceUnavailable) == ("estop: no answer from tcp://x within 5 s; "
                                                              "E-STOP NOT CONFIRMED: use the hardware E-stop")


def test_an_estop_key_does_not_wait_behind_a_command_the_service_is_slow_to_answer() -> None:
    """Space, then ``e``, while the service does not answer the stop: the E-stop goes out
    on a connection of its own and is answered; the stop's answer comes later."""
    release = threading.Event()

    class Client(RecordingClient):
        def request(self, cmd: str, **fields: Any) -> dict[str, Any]:
            if cmd == "stop":
                release.wait(10)
            return super().request(cmd, **fields)

        def __enter__(self) -> "Client":
            return self

        def __exit__(self, *exception: object) -> None:
            pass

    class Keys:
        def __init__(self) -> None:
            self.keys = [" ", "e"]

        def read(self, timeout_s: float) -> str | None:
            if self.keys:
                return self.keys.pop(0)
            time.sleep(timeout_s)
            return None

    said: list[str] = []
    thread = KeyThread(Keys(), lambda: Client({"ok": True, "message": "done"}), said.append)  # type: ignore[arg-type]
    thread.start()
    try:
        deadline = time.monotonic() + 10
        while "estop: ok: done" not in said:
            assert time.monotonic() < deadline, said
            time.sleep(0.01)
        assert "stop: ok: done" not in said  # still waiting for its answer
        release.set()
        while "stop: ok: done" not in said:
            assert time.monotonic() < deadline, said
            time.sleep(0.01)
    finally:
        release.set()
        thread.stop()


class _StatusClient(RecordingClient):
    def __enter__(self) -> "_StatusClient":
        return self

    def __exit__(self, *exception: object) -> None:
        pass


class _Keys:
    def __init__(self, *keys: str) -> None:
        self.keys = list(keys)

    def read(self, timeout_s: float) -> str | None:
        if self.keys:
            return self.keys.pop(0)
        time.sleep(timeout_s)
        return None


def _until(condition, what: str):  # noqa: ANN001, ANN202
    deadline = time.monotonic() + TIMEOUT_S  # only turns a hang into a failure
    while not (value := condition()):
        assert time.monotonic() < deadline, what
        time.sleep(0.01)
    return value


def test_telemetry_of_another_service_than_the_apis_is_said_and_only_stops_are_sent() -> None:
    """Found from outside: --api of one service and $HEXACTL_TELEMETRY of another showed the
    one platform while the keys went to the other, and nothing said so."""
    client = _StatusClient({"ok": True, "status": {"run": "api-run"}})
    services = ServiceCheck(lambda: client, "tcp://b:5555", "tcp://a:5556")  # type: ignore[arg-type,return-value]
    services.check("api-run")
    _until(lambda: client.sent == ["status"], "the API asked")
    assert services.two_services is None
    services.check("shown-run")
    two = _until(lambda: services.two_services, "the two services told apart")
    assert two.startswith("--api tcp://b:5555 and --telemetry tcp://a:5556 are two different services (run api-run "
                          "answers the API, run shown-run sends what is shown)"), two
    assert "are two different services" in rendered(RECORD, "", two)  # in red on the screen, under the legend
    said: list[str] = []
    keys = KeyThread(_Keys("x", "r", " ", ESCAPE), lambda: _StatusClient({"ok": True, "message": "done"}),  # type: ignore[arg-type,return-value]
                     said.append, lambda: services.two_services)
    keys.start()
    try:
        _until(lambda: len(said) == 4, "every key answered")
    finally:
        keys.stop()
    assert sorted(said) == sorted(["'x': not sent: " + two, "'r': not sent: " + two, "stop: ok: done", "estop: ok: done"])


def test_keys_from_a_terminal_escape_alone_or_in_a_sequence_and_the_mode_restored() -> None:
    controller, terminal = os.openpty()
    try:
        before = termios.tcgetattr(terminal)
        with KeyReader(terminal) as reader:
            assert not termios.tcgetattr(terminal)[3] & (termios.ICANON | termios.ECHO)  # cbreak, no echo
            assert reader.read(0.01) is None
            os.write(controller, b" ")
            assert reader.read(5.0) == " "
            os.write(controller, b"\x1b")
            assert reader.read(5.0) == ESCAPE
            os.write(controller, b"\x1b[A")  # an arrow key: one sequence, not an Escape
            assert reader.read(5.0) == "\x1b[A"
            os.write(controller, b"e")
            assert reader.read(5.0) == "e"
        assert termios.tcgetattr(terminal) == before
    finally:
        os.close(controller)
        os.close(terminal)


@pytest.fixture
def service(geometry, tmp_path):
    running = start_service(geometry, tmp_path, telemetry_rate_hz=100.0)
    yield running
    running.close()


@pytest.fixture(scope="module")
def geometry():
    from hexactl.adapters.files.geometry_file import load_geometry

    return load_geometry(ROOT / "config" / "platform.toml")


def test_once_prints_one_record_with_units(service, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["monitor", "--once", "--telemetry", service.telemetry]) == 0
    out = capsys.readouterr().out
    assert out.startswith("state          disabled, holding")
    assert "x    0.000 mm" in out and "yaw    0.000 deg" in out and "425.000 mm" in out
    assert "remaining      at rest" in out


def test_json_into_a_pipe_closed_early_ends_quietly(service) -> None:
    """``hexactl monitor --json | head -n 2``: a real pipe, closed after two lines."""
    monitor = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "monitor", "--json",
                                "--telemetry", service.telemetry], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        lines = [json.loads(monitor.stdout.readline()) for _ in range(2)]
        monitor.stdout.close()  # what `head` does once it has its lines
        _, stderr = monitor.communicate(timeout=TIMEOUT_S)
    finally:
        monitor.kill()
    assert [line["state"] for line in lines] == ["disabled", "disabled"]
    assert stderr.decode() == ""
    assert monitor.returncode == 0


def test_no_telemetry_is_said_with_exit_status_2(capsys: pytest.CaptureFixture[str]) -> None:
    nobody = unserved_endpoint()
    assert main(["monitor", "--once", "--telemetry", nobody, "--timeout", "0.1"]) == 2
    assert f"no telemetry from {nobody} within 0.1 s" in capsys.readouterr().err


@pytest.mark.parametrize(("change", "said"), [
    ({}, "(a sequence plays (x_sweep 2/5 (dwelling)))"),
    ({"sequence": None}, "(it is moving)"),
    ({"sequence": None, "motion": "stopping"}, "(it is stopping)"),
    ({"sequence": None, "motion": "holding"}, None),
    ({"sequence": {**RECORD["sequence"], "phase": "paused"}, "motion": "holding"}, None),
])
def test_leaving_says_so_only_while_the_platform_moves(change: dict[str, Any], said: str | None,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    say_if_moving({**RECORD, **change})
    err = capsys.readouterr().err
    if said is None:
        assert err == ""
    else:
        assert err == f"hexactl monitor: left while the platform moves {said}; it goes on: `hexactl stop` stops it\n"


def test_a_record_from_a_silent_loop_says_so_first_in_status_and_the_view() -> None:
    """A loop whose process is stopped or hung sends nothing; the API answers from its last
    report, which status and the view showed as current."""
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    silent = {**RECORD, "loop": {**RECORD["loop"], "report_age_s": 12.34}}
    first = format_telemetry(silent).splitlines()[0]
    assert first.startswith("NO LOOP REPORT for 12.3 s: the control loop's process is stopped or hung"), first
    assert "it is sent no command but stop, abort and estop" in first, first  # what the API does meanwhile (loop_silent)
    assert re.search(r"NO LOOP REPORT +for 12\.3 s: the control loop's process", rendered(silent))
    for current in (RECORD, {**RECORD, "loop": {**RECORD["loop"], "report_age_s": 0.01}}):
        assert "NO LOOP REPORT" not in format_telemetry(current) and "NO LOOP REPORT" not in rendered(current)


def test_another_controller_on_the_bus_is_said_in_status_and_the_view() -> None:
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    recent = {**RECORD, "other_controller": {"frame": "SYNC", "age_s": 0.0021}}
    assert ("OTHER CTRL     SYNC heard 0.002 s ago: another controller drives these actuators; enable is refused "
            "until it stops") in format_telemetry(recent)
    assert re.search(r"OTHER CTRL +SYNC heard 0\.002 s ago", rendered(recent))
    gone = {**RECORD, "other_controller": {"frame": "CMD_3 ENABLE", "age_s": 42.0}}
    assert "other ctrl     CMD_3 ENABLE last heard 42.0 s ago" in format_telemetry(gone)
    assert "ctrl" not in format_telemetry(RECORD).lower() and "CTRL" not in rendered(RECORD)


def test_the_links_health_is_a_row_in_status_and_the_view_red_in_the_view_when_not_active() -> None:
    from hexactl.adapters.cli.telemetry_text import format_telemetry

    healthy = {**RECORD, "link": {"bus_state": "active", "send_failures": 0, "detail": ""}}
    assert "link           CAN bus active; no send failures" in format_telemetry(healthy).splitlines()
    assert re.search(r"link +CAN bus active; no send failures", rendered(healthy))
    passive = {**RECORD, "link": {"bus_state": "passive", "send_failures": 1, "detail": "silent legs: 2"}}
    row = next(line for line in format_telemetry(passive).splitlines() if line.startswith("LINK"))
    assert row.startswith("LINK           CAN bus ERROR-PASSIVE: frames get through with errors")
    assert row.endswith("; 1 send failure; silent legs: 2")
    console = Console(file=io.StringIO(), width=200, record=True, color_system="truecolor", force_terminal=True)
    console.print(view(passive, ""))
    red_row = next(line for line in console.export_text(styles=True).splitlines() if "ERROR-PASSIVE" in line)
    assert "\x1b[1;31m" in red_row, red_row  # bold red, as the other alarms
    assert "link" not in format_telemetry(RECORD).lower().split()  # a service older than the field: no row
