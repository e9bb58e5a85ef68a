"""``hexactl serve --dashboard`` and ``hexactl demo --dashboard``: ``hexactl dashboard`` in a
process of its own beside the service, for as long as the service runs.

Its own process, as when started by hand: it is one more client of the public API and
telemetry (it adds no privilege), and its web server never competes with the control
loop's process for the GIL. It prints its URL to this process's standard output.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys

STOP_TIMEOUT_S = 5.0
"""How long the dashboard gets to end on SIGTERM before it is killed."""

log = logging.getLogger("hexactl.service")


class DashboardProcess:
    """``hexactl dashboard --http HTTP`` for the service at ``api`` and ``telemetry`` (loopback
    endpoints), started; :meth:`close` ends it, and it ends by itself if this process dies."""

    def __init__(self, api: str, telemetry: str, http: str) -> None:
        self._process = subprocess.Popen(
            [sys.executable, "-m", "hexactl.adapters.cli.main", "dashboard", "--api", api, "--telemetry", telemetry,
             "--http", http, "--exit-with", str(os.getpid())],
            stdin=subprocess.DEVNULL,
        )
        log.info("dashboard starting on http://%s/ (its own process, %d)", http, self._process.pid)

    def close(self) -> None:
        if self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
