"""``hexactl serve --dashboard``: a dashboard process that dies is said on the service's log
and started again on the same address (its pages meanwhile show that they have no live
data: test_data_loss.py)."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
from urllib.error import URLError
from urllib.request import urlopen

from tools.serving import free_port, serve, terminate, wait_until

WAIT_S = 120.0  # only a bound on a hang: a dashboard starts in seconds, a minute on a loaded host


def dashboard_children(pid: int) -> list[int]:
    children = [int(child) for task in Path(f"/proc/{pid}/task").iterdir()
                for child in (task / "children").read_text().split()]
    found = []
    for child in children:
        try:
            if b"dashboard" in Path(f"/proc/{child}/cmdline").read_bytes():
                found.append(child)
        except OSError:  # ended meanwhile
            continue
    return found


def test_a_dashboard_that_dies_is_said_and_started_again(tmp_path) -> None:
    port = free_port()
    health = f"http://127.0.0.1:{port}/health"

    def connected() -> bool:
        try:
            with urlopen(health, timeout=5) as answer:
                return json.load(answer)["connected"]
        except (URLError, OSError):
            return False

    with serve(tmp_path, "--dashboard", f"127.0.0.1:{port}") as served:
        wait_until(connected, "the dashboard serving, connected to its service", WAIT_S)
        [first] = dashboard_children(served.process.pid)
        os.kill(first, signal.SIGKILL)
        wait_until(lambda: "the dashboard's process ended (killed by SIGKILL)" in served.log, "the service to say so",
                   WAIT_S, seen=lambda: served.log)
        [second] = wait_until(lambda: [pid for pid in dashboard_children(served.process.pid) if pid != first],
                              "a new dashboard process", WAIT_S, seen=lambda: served.log)
        wait_until(connected, "the new dashboard serving on the same address", WAIT_S)
        assert served.log.count("dashboard starting on http://127.0.0.1:") == 2, served.log
        shutdown = terminate(served)
        assert shutdown.problems() == [], served.log
    assert not Path(f"/proc/{second}").exists() or \
        Path(f"/proc/{second}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
