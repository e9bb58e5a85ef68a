"""``hexactl serve`` ends on SIGTERM within a bounded time, with its API process and both
ports free, even when the API process is stuck (SIGSTOP: it answers nothing and ignores
SIGTERM); and it says what real-time set-up it got, in its log and in ``status``.

The real command in a process of its own, on random loopback ports read from its log.
"""

from __future__ import annotations

import os
import re
import signal
from pathlib import Path

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY, RealtimeConfig, allowed, probe_privileges
from tools.serving import HANG_S, serve, spawned_children, terminate, wait_until


def gone(pid: int) -> bool:
    """No such process, or only a zombie of one (dead, not yet reaped by whoever adopted it)."""
    try:
        return (Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]) == "Z"
    except OSError:
        return True


def enable_and_move(client: HexactlClient) -> None:
    """Enable and start a long move. On a loaded host the loop's verdict may come too late
    for the API (``loop_timeout``): the platform is then enabled all the same (waited
    for), and moving or not, which both exercise the shutdown's brake-and-disable path."""
    try:
        client.call("enable")
    except CommandError as error:
        assert error.code == "loop_timeout", error
    wait_until(lambda: client.call("status")["status"]["state"] == "enabled", "the platform enabled", HANG_S,
               seen=lambda: client.call("status")["status"]["state"])
    try:
        client.call("move", pose=[150.0, 0, 0, 0, 0, 0], duration=5.0)
    except CommandError as error:
        assert error.code in ("loop_timeout", "expired"), error


def test_sigterm_ends_the_service_and_its_stuck_api_process(tmp_path: Path) -> None:
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=10) as client:
            enable_and_move(client)
        [api_process] = spawned_children(served.process.pid)
        os.kill(api_process, signal.SIGSTOP)  # stuck: answers nothing, and SIGTERM would not end it
        shutdown = terminate(served)
        print(f"hexactl serve with a stuck API process: {shutdown}; its log:\n{served.log}")
        assert shutdown.problems() == [], served.log
        assert gone(api_process), f"the API process {api_process} is left:\n{served.log}"
    log = served.log
    assert "did not end within" in log and "killed" in log
    # Unless a loaded host stalled the simulator meanwhile (a fault latched: the actuators
    # hold), the platform was braked, its place logged, and the actuators disabled.
    if not re.search(r"fault at x [-0-9.]+ mm, .* deg \(measured\): nothing to brake", log):
        assert re.search(r"platform (at rest|still moving) at x [-0-9.]+ mm, .* yaw [-0-9.]+ deg", log), log
        assert "actuators disabled" in log, log
    assert re.search(r"stopped \(shutdown took \d+\.\d\d s\)$", log.rstrip()), log


def test_the_service_says_what_real_time_set_up_it_got_and_no_realtime_opts_out(tmp_path: Path) -> None:
    priority, locked, notes = allowed(RealtimeConfig(fifo_priority=DEFAULT_FIFO_PRIORITY, lock_memory=True),
                                      probe_privileges())
    for options, expected in (((), (priority, locked)), (("--no-realtime",), (None, False))):
        with serve(tmp_path, *options) as served:
            with HexactlClient(served.api, timeout_s=10) as client:
                realtime = client.call("status")["status"]["realtime"]
            shutdown = terminate(served)
            print(f"hexactl serve {' '.join(options)}: {shutdown}")
            assert shutdown.problems() == [], served.log
        assert (realtime["fifo_priority"], realtime["memory_locked"]) == expected, realtime
        if options:
            assert realtime["notes"] == [] and "real-time: normal scheduling, memory not locked" in served.log
        else:
            assert set(notes) <= set(realtime["notes"])  # what the privileges left out, and why
            scheduling = f"SCHED_FIFO {priority}" if priority else "normal scheduling"
            assert f"real-time: {scheduling}, memory {'locked' if locked else 'not locked'}" in served.log
        assert "nothing to brake" in served.log and "actuators disabled" not in served.log  # never enabled


def test_a_hangup_brakes_and_disables_as_sigterm_does(tmp_path: Path) -> None:
    """The terminal or SSH session of a foreground ``hexactl serve`` goes: SIGHUP reaches
    its whole process group. It used to kill the service and its API process on the spot,
    mid-motion, leaving each actuator to stop on its own watchdog."""
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=10) as client:
            enable_and_move(client)
        [api_process] = spawned_children(served.process.pid)
        os.kill(api_process, signal.SIGHUP)  # the group's members, the API process first: the worst order
        os.kill(served.process.pid, signal.SIGHUP)
        status = served.wait(HANG_S)
    log = served.log
    assert status == 0 and "SIGHUP: shutting down" in log, log
    assert "the API process died" not in log, log
    if not re.search(r"fault at x [-0-9.]+ mm, .* deg \(measured\): nothing to brake", log):  # as above
        assert re.search(r"platform (at rest|still moving) at x [-0-9.]+ mm, .* yaw [-0-9.]+ deg", log), log
        assert "actuators disabled" in log, log
