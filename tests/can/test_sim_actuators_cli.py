"""``hexactl sim-actuators`` in its own process: what its ready line says is what it runs under."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

START_S = 60.0  # bounds a hang only: the process's imports take seconds on a busy host


def _ready_then_stopped(*options: str) -> tuple[dict, int, int]:
    """Start the simulator on a ``virtual:`` bus, read its ready line and its scheduling
    (policy, priority) from the kernel, stop it with SIGTERM and expect the final line."""
    process = subprocess.Popen([sys.executable, "-m", "hexactl.adapters.cli.main", "sim-actuators",
                                "--can", "virtual:sim-actuators-cli", *options],
                               stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        ready = json.loads(process.stdout.readline() or "{}")
        assert ready.get("ready"), process.stderr.read()
        policy = os.sched_getscheduler(process.pid) & ~os.SCHED_RESET_ON_FORK
        priority = os.sched_getparam(process.pid).sched_priority
        process.terminate()
        out, err = process.communicate(timeout=START_S)
        assert process.returncode == 0, err
        assert json.loads(out.splitlines()[-1])["stopped"]
        return ready, policy, priority
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_fifo_is_set_once_ready_or_the_ready_line_says_why_not() -> None:
    ready, policy, priority = _ready_then_stopped("--fifo", "7")
    if ready["scheduling"] == "SCHED_FIFO 7":
        assert (policy, priority) == (os.SCHED_FIFO, 7)
    else:  # a host that does not permit it: normal scheduling, and the reason in words
        assert ready["scheduling"].startswith("SCHED_FIFO 7 not set: "), ready["scheduling"]
        assert policy == os.SCHED_OTHER


def test_without_fifo_it_keeps_normal_scheduling() -> None:
    ready, policy, _ = _ready_then_stopped()
    assert ready["scheduling"] == "normal scheduling" and policy == os.SCHED_OTHER


@pytest.mark.parametrize("priority", ["0", "100", "high"])
def test_a_priority_out_of_range_is_refused(priority: str) -> None:
    done = subprocess.run([sys.executable, "-m", "hexactl.adapters.cli.main", "sim-actuators",
                           "--can", "virtual:x", "--fifo", priority],
                          capture_output=True, text=True, timeout=START_S)  # fmt: skip
    assert done.returncode == 2 and "argument --fifo" in done.stderr
