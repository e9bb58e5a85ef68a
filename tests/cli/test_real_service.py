"""The client command line against ``hexactl serve`` run as an operator runs it (a process
in its own working directory, loopback ports): the README's ``load-calibration`` of the
demo's result and ``save-recording recordings/run1.csv``, the goal of a leg-locked move,
and where Ctrl-C left the platform (hexactl issue 16)."""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.protocol import default_client_name
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from tests.reliability.support import (ATTEMPTS, braked_since, last_event, recover, recovered_client,
                                       recovered_client_fixture, stalled, status, tolerating_stalls, wait_for)
from tools.serving import HANG_S, Served, serve

WAIT_S = 30.0  # generous: the simulator and the loop share a possibly busy machine


@pytest.fixture(scope="module")
def directory(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("operator")


@pytest.fixture(scope="module")
def served(directory: Path) -> Iterator[Served]:
    with serve(directory) as running:
        yield running


client = recovered_client_fixture(WAIT_S)


def hexactl(served: Served, *arguments: str) -> int:
    return main([*arguments, "--api", served.api, "--timeout", str(WAIT_S)])


def printed(served: Served, capsys: pytest.CaptureFixture[str], *arguments: str, exit_status: int = 0) -> tuple[str, str]:
    """What ``hexactl *arguments`` printed (stdout stripped, stderr), having exited ``exit_status``."""
    capsys.readouterr()
    assert hexactl(served, *arguments) == exit_status
    out, err = capsys.readouterr()
    return out.strip(), err


def at_rest(client: HexactlClient) -> bool:
    record = status(client)
    assert record["state"] == "enabled", f"{record['state']}: {record['faults']}"
    return record["motion"] == "holding" and record["sequence"] is None


def test_the_readme_session_runs_as_written(served, directory, client, monkeypatch, capsys) -> None:
    """From the service's working directory: the demo's calibration loads from
    ``demo-out/`` (not a data directory: read here and sent), a recording saves into
    ``recordings/`` (created by serve)."""
    monkeypatch.chdir(directory)
    (directory / "demo-out").mkdir()
    demo = load_geometry(default_config_path()).model_copy(update={"name": "demo"})
    (directory / "demo-out" / "calibration.toml").write_text(geometry_to_toml(demo))
    recording = directory / "recordings" / "run1.csv"

    def scenario() -> None:
        capsys.readouterr()
        assert hexactl(served, "load-calibration", "demo-out/calibration.toml") == 0
        assert capsys.readouterr().out.startswith(
            f"ok: calibration {geometry_id(demo)} loaded; kept for a restart in {directory / 'active_calibration.toml'};"
            f" read from {directory / 'demo-out' / 'calibration.toml'} here and sent")
        assert hexactl(served, "play", "x_sweep") == 0
        assert hexactl(served, "save-recording", "recordings/run1.csv") == 0
        assert recording.is_file()
        assert hexactl(served, "abort") == 0
        wait_for(lambda: at_rest(client), "the platform at rest")

    tolerating_stalls(client, scenario, cleanup=lambda: recording.unlink(missing_ok=True))


README = Path(__file__).resolve().parents[2] / "README.md"
INTERACTIVE = ("hexactl monitor", "hexactl events --follow")
"""README lines a script cannot run: the monitor's screen (tests/cli/test_monitor_tmux.py),
events followed until Ctrl-C (tests/cli/test_events_command.py)."""


def readme_session() -> list[str]:
    """The command lines of README.md's "Running the controller" session, comments cut."""
    text = README.read_text(encoding="utf-8")
    block = text[text.index("From another terminal in the same directory"):]
    block = block[block.index("```sh\n") + len("```sh\n"):block.index("\n```", block.index("```sh\n"))]
    lines = [re.sub(r"\s+#.*$", "", line).strip() for line in block.splitlines()]
    return [line for line in lines if line and line not in INTERACTIVE]


def test_the_readme_session_runs_line_by_line_as_written(served, directory, client, tmp_path) -> None:
    """Every line of the README's session, through a shell, in the service's working
    directory, with ``hexactl`` on the PATH and the endpoint from ``HEXACTL_API``: each
    exits 0. ``demo-out/calibration.toml`` stands for ``hexactl demo``'s result."""
    (directory / "demo-out").mkdir(exist_ok=True)
    demo = load_geometry(default_config_path()).model_copy(update={"name": "demo", "zero_lengths": (1751.0,) * 6})
    (directory / "demo-out" / "calibration.toml").write_text(geometry_to_toml(demo))
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "hexactl").write_text(f"#!/bin/sh\nexec {sys.executable} -m hexactl.adapters.cli.main \"$@\"\n")
    (bin_dir / "hexactl").chmod(0o755)
    environment = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "HEXACTL_API": served.api,
                   "PYTHONPATH": str(README.parent)}
    session = readme_session()
    assert len(session) > 12 and "hexactl load-calibration demo-out/calibration.toml" in session

    recordings = directory / "recordings"

    def run(line: str) -> None:
        """Run ``line``; if it failed with only a stall's faults latched, or after the service
        braked on its API's silence (a busy host held the loop, the simulated actuators or
        the API up: what the service must do, not what this tests; ``play --wait`` exits 1
        when its sequence is cut short so), bring the service back to where the line expects
        it, remove what the failed attempt wrote, and run that line again (ATTEMPTS in all)."""
        before = set(recordings.iterdir())
        for attempt in range(1, ATTEMPTS + 1):
            since = last_event(status(client))
            ran = subprocess.run(["bash", "-c", line], cwd=directory, env=environment, capture_output=True, text=True,
                                 timeout=300)
            if ran.returncode == 0:
                return
            failure = f"{line!r} exited {ran.returncode}:\n{ran.stdout}{ran.stderr}"
            braked = braked_since(client, since)
            print(f"attempt {attempt} failed: {failure}; latched: {status(client)['faults']}"
                  + ("; the service braked when its API fell silent" if braked else ""))
            assert attempt < ATTEMPTS and (stalled(client) or braked), failure
            for made in set(recordings.iterdir()) - before:
                made.unlink()
            if status(client)["state"] != "enabled":  # latched: reset, to disabled as a line after a reset expects
                client.request("reset")
                wait_for(lambda: status(client)["state"] == "disabled", "the reset")
            if line != "hexactl enable":
                recover(client)

    client.request("disable")  # as a service just started: the session enables it
    for made in ("run1.csv", "run2.csv", "run2.json", "run2.png"):  # the module's other tests save some too
        (recordings / made).unlink(missing_ok=True)
    try:
        for line in session:
            run(line)
    finally:
        client.request("clear_frames")


def test_a_leg_locked_move_prints_the_goal_it_runs_to(served, client, capsys) -> None:
    def scenario() -> None:
        assert hexactl(served, "leg-lock", "3") == 0
        try:
            capsys.readouterr()
            assert hexactl(served, "move", "x=50") == 0
            out = capsys.readouterr().out
            assert re.search(r"^ok: moving; goal x +-?\d+\.\d{3} mm +y +-?\d+\.\d{3} mm .* yaw +-?\d+\.\d{3} deg "
                             r"\(projected onto the locked leg's constraint\); \d+\.\d\d s$", out.strip()), out
            assert "x   50.000 mm" not in out  # the projection moved it
            wait_for(lambda: at_rest(client), "the platform at rest")
        finally:
            client.request("leg_unlock")  # refused while a fault is latched: the retry's recover resets
        assert hexactl(served, "move", "x=20") == 0
        out = capsys.readouterr().out  # unlocked: the goal is the pose asked for, not projected
        assert "goal x   20.000 mm" in out and "projected" not in out, out
        wait_for(lambda: at_rest(client), "the platform at rest")

    tolerating_stalls(client, scenario)


def test_ctrl_c_mid_move_logs_where_the_platform_came_to_rest(tmp_path) -> None:
    with serve(tmp_path) as running:
        with recovered_client(running.api, WAIT_S) as connected:

            def moving() -> None:
                reply = connected.request("move", pose=[0.0, 0.0, 100.0, 0.0, 0.0, 0.0], duration=30.0)
                assert reply["ok"], reply
                wait_for(lambda: status(connected)["motion"] == "moving", "the move")

            tolerating_stalls(connected, moving)
        running.process.send_signal(signal.SIGINT)
        assert running.wait(HANG_S) == 0, running.log
    pose = r"x -?\d+\.\d{3} mm, y -?\d+\.\d{3} mm, z -?\d+\.\d{3} mm, roll -?\d+\.\d{3} deg, pitch -?\d+\.\d{3} deg, " \
           r"yaw -?\d+\.\d{3} deg"
    # Unless a loaded host stalled the simulator (a fault latched: the actuators hold where it caught them).
    braked = re.search(rf"platform (at rest|still moving) at {pose} \(commanded, relative to the zero posture; "
                       rf"measured {pose}\)", running.log)
    assert braked or re.search(rf"fault at {pose} \(measured\): nothing to brake", running.log), running.log


def test_wait_says_when_a_stop_left_the_move_short_of_its_goal(served, client) -> None:
    """At rest is not arrived: a move that another client stopped (or the service, when its
    API fell silent) ends ``--wait`` with status 1 and where it rests."""

    def scenario() -> None:
        moving = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "move", "z=40", "--duration",
                                   "20", "--wait", "--api", served.api],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for(lambda: moving.poll() is not None or status(client)["motion"] == "moving", "the move")
        assert moving.poll() is None, moving.communicate()  # refused (a stall's fault latched): said, tried again
        client.request("stop")
        _, err = moving.communicate(timeout=WAIT_S)
        assert moving.returncode == 1, err
        assert "hexactl move: stopped short of its goal, at x " in err, err
        # Who stopped it: the name this test's client gave, and where it came from.
        assert (f"the service recorded since it started: stop: any motion under way brakes to rest, sent by "
                f"{default_client_name()} (127.0.0.1) (") in err, err
        assert hexactl(served, "move", "z=0", "--duration", "1", "--wait") == 0  # one that arrives: 0

    tolerating_stalls(client, scenario)


def test_wait_says_when_a_stop_or_an_abort_cut_a_sequence_short(served, client) -> None:
    """Found from outside: ``play --wait`` and ``resume --wait`` exited 0 when a stop or an
    abort ended the sequence (a play has no goal to come to rest short of), so
    ``hexactl play seq --wait && next-step`` went on as if it had played to its end."""

    def waiting(*command: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", *command, "--wait", "--api",
                                 served.api], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def scenario() -> None:
        playing = waiting("play", "x_sweep")
        wait_for(lambda: (status(client).get("sequence") or {}).get("phase") == "moving", "the sequence to play")
        client.request("stop")
        _, err = playing.communicate(timeout=WAIT_S)
        assert playing.returncode == 1, err
        assert "hexactl play: sequence x_sweep ended aborted, before its end" in err, err
        assert "the service recorded since it started: sequence_aborted: " in err, err
        assert f"stop: any motion under way brakes to rest, sent by {default_client_name()}" in err, err
        wait_for(lambda: at_rest(client), "the platform at rest")
        assert client.request("play", sequence="x_sweep")["ok"]
        wait_for(lambda: (status(client).get("sequence") or {}).get("phase") == "moving", "the sequence to play")
        client.request("pause")
        wait_for(lambda: (status(client).get("sequence") or {}).get("phase") == "paused", "the pause")
        resuming = waiting("resume")
        wait_for(lambda: status(client)["motion"] == "moving", "the sequence to resume")
        client.request("abort")
        _, err = resuming.communicate(timeout=WAIT_S)
        assert resuming.returncode == 1, err
        assert "hexactl resume: sequence x_sweep ended aborted, before its end" in err, err
        wait_for(lambda: at_rest(client), "the platform at rest")

    tolerating_stalls(client, scenario)


def test_wait_returns_at_rest_and_says_when_a_pause_or_an_estop_holds_the_motion(served, client, capsys) -> None:
    def scenario() -> None:
        assert hexactl(served, "move", "z=30", "--duration", "1", "--wait") == 0
        assert at_rest(client) and status(client)["pose_command"][2] == pytest.approx(30.0, abs=1e-6)
        playing = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "play", "x_sweep", "--wait",
                                    "--api", served.api], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for(lambda: (status(client).get("sequence") or {}).get("phase") == "moving", "the sequence to play")
        client.request("pause")
        _, err = playing.communicate(timeout=WAIT_S)
        assert playing.returncode == 1 and "sequence x_sweep is paused: `hexactl resume` or `hexactl abort`" in err
        resuming = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "resume", "--wait",
                                     "--api", served.api], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # Its reply first (the ok line, flushed), then the E-stop it waits through: an E-stop
        # that came before the reply cancels the resume instead, rightly ("resume cancelled:
        # a stop, abort or estop arrived while it was being planned"), and --wait is not reached.
        replied, _, _ = select.select([resuming.stdout], [], [], WAIT_S)
        assert replied and resuming.stdout.readline().startswith("ok: "), "the resume's reply"
        wait_for(lambda: status(client)["motion"] == "moving", "the sequence to resume")
        client.request("estop")
        _, err = resuming.communicate(timeout=WAIT_S)
        assert resuming.returncode == 1 and "the motion ended: the controller is estop" in err
        assert "once its cause is dealt with, `hexactl reset`, then `hexactl enable`" in err

    try:
        tolerating_stalls(client, scenario)
    finally:
        client.request("reset")


def test_move_validate_shows_the_whole_goal_and_moves_nothing(served, client, capsys) -> None:
    """Found from outside: with a work frame 20 mm up and the tool 100 mm out, `move x=5
    --frame work` ran to z −80 mm (the axes not given are 0, as documented), which the
    reply showed only once the platform was moving. --validate shows it first."""
    def scenario() -> None:
        assert hexactl(served, "frames", "--work", "z=20", "--tool", "z=100") == 0
        try:
            before = status(client)["pose_command"]
            out, _ = printed(served, capsys, "move", "x=5", "--frame", "work", "--validate")
            assert re.search(r"^ok: .*valid, nothing moved: goal x +5\.000 mm .* z +-80\.000 mm .*\(relative to the "
                             r"zero posture\); tool x +5\.000 mm .* \(in the work frame\); \d+\.\d\d s$", out), out
            assert status(client)["pose_command"] == before and at_rest(client)
            _, err = printed(served, capsys, "move", "x=5", "--validate", "--wait", exit_status=2)  # nothing to wait for
            assert "--validate moves nothing" in err
            assert "path_violation" in printed(served, capsys, "move", "x=5000", "--validate", exit_status=1)[1]
        finally:
            client.request("clear_frames")

    tolerating_stalls(client, scenario)


def test_play_validate_says_how_far_a_leg_lock_moves_the_waypoints_and_plays_nothing(served, directory, client,
                                                                                      capsys) -> None:
    """Found from outside: a sequence played with a leg locked ran to projected waypoints,
    up to 25 mm from the file's, and nothing said so; nor could a sequence be checked
    before it played."""
    steps = directory / "sequences" / "steps.toml"
    steps.write_text('name = "steps"\n[[waypoint]]\npose = [0, 0, 6, 0, 0, 0]\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\n')

    def scenario() -> None:
        assert hexactl(served, "move", "0,0,0,0,0,0", "--wait") == 0  # the lock taken where waypoint 2 is
        before = status(client)["pose_command"]
        out, _ = printed(served, capsys, "play", str(steps), "--validate")
        assert re.fullmatch(r"ok: valid, nothing moved: it ends at x +0\.000 mm .* yaw +0\.000 deg \(relative "
                            r"to the zero posture\); 2 waypoints; \d+\.\d\d s", out), out
        assert hexactl(served, "leg-lock", "3") == 0
        try:
            out, _ = printed(served, capsys, "play", str(steps), "--validate")
            assert re.search(r"; 2 waypoints; projected onto the locked leg's constraint: waypoints move by up to "
                             r"[1-9]\d*\.\d{3} mm \(waypoint 1\); \d+\.\d\d s$", out), out
            assert status(client)["pose_command"] == before and at_rest(client)
            _, err = printed(served, capsys, "play", "steps", "--validate", "--wait", exit_status=2)  # nothing to wait for
            assert "--validate plays nothing" in err
        finally:
            client.request("leg_unlock")  # refused while a fault is latched: the retry's recover resets
        far = directory / "sequences" / "far.toml"
        far.write_text('name = "far"\n[[waypoint]]\npose = [0, 0, 5000, 0, 0, 0]\n')
        assert "error path_violation: " in printed(served, capsys, "play", str(far), "--validate", exit_status=1)[1]

    tolerating_stalls(client, scenario)
