"""``hexactl monitor`` in a real terminal (issue 16's "Done when"): a detached tmux session
runs it against a service on the simulator; keys are typed with ``send-keys``, the screen
read with ``capture-pane``, and what the keys did is checked through the API.

tmux is installed if missing (apt-get, as root: see tools/_debian.py). Each test uses a
tmux server of its own (``-L hexactl-test-<pid>-<n>``), killed at the end."""

from __future__ import annotations

import functools
import itertools
import os
import shlex
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from tests.api.test_service import wait_for as service_wait_for
from tests.reliability.support import recover, recovered_client_fixture, tolerating_stalls
from tools._debian import ensure_executables
from tools.serving import Served, serve

ROOT = Path(__file__).resolve().parents[2]
WAIT_S = 60.0  # generous: only turns a hang into a failure on a busy machine
LONG_MOVE = {"pose": [0, 0, 80, 0, 0, 5], "duration": 60.0}  # still moving whenever a key is sent

_servers = itertools.count()


wait_for = functools.partial(service_wait_for, timeout_s=WAIT_S)


class Terminal:
    """A detached 120×40 tmux session running one command, on a tmux server of its own."""

    def __init__(self, tmux: str, command: str, columns: int = 120, lines: int = 40) -> None:
        self._tmux = [tmux, "-L", f"hexactl-test-{os.getpid()}-{next(_servers)}", "-f", "/dev/null"]
        # The pane outlives the command, so that what it printed on leaving can be read; the
        # shell survives the Ctrl-C sent to the monitor (its handler is not inherited).
        # COLUMNS and LINES as a shell (or readline in this process) may have exported them,
        # wrong: the monitor must go by the terminal's own size.
        self.run("new-session", "-d", "-x", str(columns), "-y", str(lines), "-s", "monitor",
                 f"trap : INT; export COLUMNS=80 LINES=24; {command}; echo monitor exited $?; sleep 600")

    def run(self, *arguments: str) -> str:
        return subprocess.run([*self._tmux, *arguments], check=True, capture_output=True, text=True,
                              timeout=WAIT_S).stdout

    def screen(self) -> str:
        return self.run("capture-pane", "-p", "-t", "monitor")

    def keys(self, *keys: str) -> None:
        self.run("send-keys", "-t", "monitor", *keys)

    def wait_for_screen(self, *texts: str) -> str:
        def showing() -> str | None:
            screen = self.screen()
            return screen if all(text in screen for text in texts) else None

        return wait_for(showing, f"{texts} on the screen")

    def kill(self) -> None:
        subprocess.run([*self._tmux, "kill-server"], capture_output=True, timeout=WAIT_S)


@pytest.fixture(scope="module")
def tmux() -> str:
    return ensure_executables({"tmux": "tmux"}, lambda line: print(line, file=sys.stderr))["tmux"]


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """``hexactl serve`` in a process of its own, as an operator runs it. Not in this one: its
    loop waited for the GIL whenever this process's main thread (tmux calls) was preempted
    holding it on a busy host, and the actuators' watchdog latched a fault mid-test."""
    with serve(tmp_path_factory.mktemp("served")) as running:
        yield running


client = recovered_client_fixture(WAIT_S)


def monitor_command(served: Served) -> str:
    command = shlex.join(["env", f"PYTHONPATH={ROOT}", sys.executable, "-m", "hexactl.adapters.cli.main", "monitor",
                          "--api", served.api, "--telemetry", served.telemetry])
    return f"cd {shlex.quote(str(ROOT))} && {command}"


@pytest.fixture
def terminal(tmux, served) -> Iterator[Terminal]:
    opened = Terminal(tmux, monitor_command(served))
    yield opened
    opened.kill()


def status(client: HexactlClient) -> dict:
    return client.call("status")["status"]


def moving(client: HexactlClient, then: Callable[[], object] = lambda: None) -> None:
    """Enabled (after a reset if need be) and on a long move, then ``then()``: all again if it
    failed while a loaded host's stall had latched a fault (beside another suite's run the
    actuators' watchdog did, between the move and a key's check)."""
    def attempt() -> None:
        recover(client)
        client.call("move", **LONG_MOVE)
        wait_for(lambda: status(client)["motion"] == "moving", "the move to start")
        then()

    tolerating_stalls(client, attempt)


def test_the_monitor_shows_the_values_with_units_in_place_and_its_keys_stop_the_platform(terminal, client) -> None:
    def shown_and_stopped_by_space() -> None:
        screen = terminal.wait_for_screen("ENABLED", "moving", "remaining", "x mm", "yaw deg", "L1 mm", "goal", "µs")
        goal_row = next(line.split() for line in screen.splitlines() if line.startswith("goal"))
        assert goal_row[1:] == ["0.000", "0.000", "80.000", "0.000", "0.000", "5.000"]
        assert "space stop" in screen and "Esc or e E-STOP" in screen and "q quit" in screen
        assert screen.splitlines()[0].endswith("x reset · q quit")  # on the pane's 120 columns, not COLUMNS' 80
        terminal.keys("Space")
        wait_for(lambda: status(client)["motion"] == "holding", "the platform at rest after space")
        assert status(client)["state"] == "enabled"
        terminal.wait_for_screen("stop: ok")

    moving(client, shown_and_stopped_by_space)

    def e_stopped_by_e() -> None:
        terminal.keys("e")
        wait_for(lambda: status(client)["state"] == "estop", "E-stop latched after e")
        terminal.wait_for_screen("ESTOP", "estop: ok")

    moving(client, e_stopped_by_e)

    terminal.keys("x")
    wait_for(lambda: status(client)["state"] == "disabled", "reset after x")

    def e_stopped_by_escape() -> None:
        terminal.keys("Escape")
        wait_for(lambda: status(client)["state"] == "estop", "E-stop latched after Escape")

    moving(client, e_stopped_by_escape)

    # Redrawn in place on the alternate screen: nothing went into the scrollback.
    assert terminal.run("display-message", "-p", "-t", "monitor", "#{history_size}").strip() == "0"


def test_on_a_screen_too_short_for_the_record_the_keys_answer_still_shows(tmux, served, client) -> None:
    short = Terminal(tmux, monitor_command(served), columns=100, lines=16)
    try:
        short.wait_for_screen("hexactl monitor", "x mm")

        def stopped_by_space() -> None:
            short.keys("Space")
            wait_for(lambda: status(client)["motion"] == "holding", "the platform at rest after space")
            assert status(client)["state"] == "enabled"
            screen = short.wait_for_screen("stop: ok")
            assert len(screen.rstrip("\n").splitlines()) <= 16 and "real-time" not in screen  # the record's end cut

        moving(client, stopped_by_space)
    finally:
        short.kill()


def _leave_while_moving(terminal: Terminal, client: HexactlClient, key: str, exit_status: int) -> str:
    """Set the platform moving under the monitor and leave it with ``key``: the screen after."""
    terminal.wait_for_screen("hexactl monitor", "x mm")
    moving(client, lambda: terminal.wait_for_screen("moving"))
    terminal.keys(key)
    return terminal.wait_for_screen(f"monitor exited {exit_status}")


def test_leaving_while_the_platform_moves_says_how_to_stop_it(terminal, client) -> None:
    screen = _leave_while_moving(terminal, client, "q", 0)
    assert "left while the platform moves (it is moving); it goes on: `hexactl stop` stops it" in screen
    assert status(client)["motion"] == "moving"  # leaving stopped nothing
    client.call("stop")


def test_ctrl_c_leaves_with_the_terminal_restored(terminal, client) -> None:
    screen = _leave_while_moving(terminal, client, "C-c", 130)
    assert "`hexactl stop` stops it" in screen
    client.call("stop")
    # The shell's terminal is back in canonical mode with echo: a typed line shows and runs.
    terminal.keys("echo typed-after", "Enter")
    terminal.wait_for_screen("typed-after")
