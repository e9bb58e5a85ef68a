"""``hexactl serve --dashboard`` and ``hexactl demo --dashboard``: ``hexactl dashboard`` in a
process of its own beside the service, for as long as the service runs.

Its own process, as when started by hand: it is one more client of the public API and
telemetry (it adds no privilege), and its web server never competes with the control
loop's process for the GIL. It prints its URL to this process's standard output.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time

STOP_TIMEOUT_S = 5.0
"""How long the dashboard gets to end on SIGTERM before it is killed."""

FIRST_RESTART_DELAY_S = 1.0
"""A dashboard that ended is started again after this long, twice as long after each end
that follows within :data:`STEADY_S` of its start (a crash at start-up), at most
:data:`MOST_RESTART_DELAY_S`."""
MOST_RESTART_DELAY_S = 60.0
STEADY_S = 60.0

WATCH_INTERVAL_S = 0.5
"""How often the dashboard's process is looked at."""

log = logging.getLogger("hexactl.service")


class DashboardProcess:
    """``hexactl dashboard --http HTTP`` for the service at ``api`` and ``telemetry`` (loopback
    endpoints), started; :meth:`close` ends it, and it ends by itself if this process dies.
    A thread of its own looks at it every :data:`WATCH_INTERVAL_S`, says when it has ended
    and starts it again, whatever this process's main thread is doing (``hexactl serve``
    waits for signals, ``hexactl demo`` runs its campaign)."""

    def __init__(self, api: str, telemetry: str, http: str) -> None:
        self._command = [sys.executable, "-m", "hexactl.adapters.cli.main", "dashboard", "--api", api,
                         "--telemetry", telemetry, "--http", http, "--exit-with", str(os.getpid())]
        self._http = http
        self._delay_s = FIRST_RESTART_DELAY_S
        self._restart_at: float | None = None  # monotonic s: when to start it again (None: it runs)
        self._process = self._start()
        self._closing = threading.Event()
        self._watcher = threading.Thread(target=self._watch_until_closed, name="hexactl-dashboard-watch", daemon=True)
        self._watcher.start()

    def _watch_until_closed(self) -> None:
        while not self._closing.wait(WATCH_INTERVAL_S):
            self._watch()

    def _start(self) -> subprocess.Popen:
        process = subprocess.Popen(self._command, stdin=subprocess.DEVNULL)
        self._started_at = time.monotonic()
        log.info("dashboard starting on http://%s/ (its own process, %d)", self._http, process.pid)
        return process

    def _watch(self) -> None:
        """Log a dashboard that has ended (its pages lose their live data and say so) and
        start it again once its delay is over."""
        now = time.monotonic()
        if self._restart_at is None:
            if (status := self._process.poll()) is None:
                return
            if now - self._started_at >= STEADY_S:
                self._delay_s = FIRST_RESTART_DELAY_S
            how = f"killed by {signal.Signals(-status).name}" if status < 0 else f"exit status {status}"
            log.error("the dashboard's process ended (%s): its pages have no live data and no E-stop; starting it "
                      "again in %g s", how, self._delay_s)
            self._restart_at = now + self._delay_s
            self._delay_s = min(2 * self._delay_s, MOST_RESTART_DELAY_S)
        elif now >= self._restart_at:
            self._restart_at = None
            self._process = self._start()

    def close(self) -> None:
        self._closing.set()
        self._watcher.join()  # first: it must not start a dashboard after this one is ended
        if self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
