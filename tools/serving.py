"""``hexactl serve`` in a process of its own, as an operator runs it: started in a working
directory on loopback ports (or the endpoints given), its log read all along, ended with
SIGTERM and checked against the promise a service manager relies on: exit status 0
within :data:`SHUTDOWN_BOUND_S`, both endpoints free to bind again.

One helper for the tests and tools that need the real command (``tools/file_race.py``,
``tests/api``, ``tests/reliability``)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import zmq

LOOPBACK = "tcp://127.0.0.1:*"

SHUTDOWN_BOUND_S = 10.0
"""The most ``hexactl serve`` may take from SIGTERM to its exit (hexactl issue 10): the
service's own bounded shutdown and backstop keep it there on a loaded host."""

HANG_S = 60.0
"""How long :func:`terminate` waits for an exit at all, so that a slow exit is measured
(and judged against :data:`SHUTDOWN_BOUND_S`) rather than cut short."""

START_TIMEOUT_S = 300.0
"""Seconds on an idle host; minutes when other work loads it (the API process is spawned
and imports everything anew)."""

_SERVING = re.compile(r"API on (?P<api>\S+), telemetry on (?P<telemetry>\S+) at")


@dataclass
class Served:
    """A running ``hexactl serve``: its process, endpoints, and its log as it grows."""

    process: subprocess.Popen[str]
    api: str = ""
    telemetry: str = ""
    lines: list[str] = field(default_factory=list)
    reader: threading.Thread | None = None

    @property
    def log(self) -> str:
        return "".join(self.lines)

    def wait(self, timeout_s: float) -> int:
        """The exit status, once the process has exited and its whole log is read.

        :raises subprocess.TimeoutExpired: if it still runs after ``timeout_s``
        """
        status = self.process.wait(timeout_s)
        if self.reader is not None:
            self.reader.join(timeout_s)
        return status


@dataclass(frozen=True)
class Shutdown:
    """How ``hexactl serve`` ended on SIGTERM: its exit status (None: still running after
    :data:`HANG_S`, then killed), the seconds it took, and the endpoints still taken after."""

    exit_status: int | None
    seconds: float
    endpoints_in_use: tuple[str, ...]

    def problems(self) -> list[str]:
        """Every way the shutdown broke the promise (empty: it kept it)."""
        found = []
        if self.exit_status is None:
            found.append(f"hexactl serve still ran {HANG_S:g} s after SIGTERM")
        elif self.exit_status != 0:
            found.append(f"hexactl serve exited with status {self.exit_status} on SIGTERM")
        elif self.seconds > SHUTDOWN_BOUND_S:
            found.append(f"hexactl serve took {self.seconds:.2f} s to exit on SIGTERM (bound {SHUTDOWN_BOUND_S:g} s)")
        if self.endpoints_in_use:
            found.append(f"still in use after the exit: {', '.join(self.endpoints_in_use)}")
        return found

    def __str__(self) -> str:
        return (f"SIGTERM: exit status {self.exit_status} after {self.seconds:.2f} s; "
                f"in use after: {', '.join(self.endpoints_in_use) or 'nothing'}")


@contextmanager
def serve(directory: Path, *options: str, api: str = LOOPBACK, telemetry: str = LOOPBACK) -> Iterator[Served]:
    """``hexactl serve *options`` with ``directory`` as its working directory (so its data
    directories are there by default), started; killed on the way out if still running
    (:func:`terminate` is the clean end).

    :raises RuntimeError: if it exits, or does not say where it serves within
        :data:`START_TIMEOUT_S`
    """
    process = subprocess.Popen(
        [sys.executable, "-m", "hexactl.adapters.cli.main", "serve", "--api", api, "--telemetry", telemetry, *options],
        stderr=subprocess.PIPE, text=True, cwd=directory, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    served = Served(process)
    started = threading.Event()

    def read() -> None:  # the whole log, all along: a full pipe would block the service's logging
        assert process.stderr is not None
        for line in process.stderr:
            served.lines.append(line)
            if found := _SERVING.search(line):
                served.api, served.telemetry = found["api"], found["telemetry"]
                started.set()
        started.set()  # exited: the caller finds no endpoints

    reader = served.reader = threading.Thread(target=read, name="serve-log", daemon=True)
    reader.start()
    try:
        if not started.wait(START_TIMEOUT_S) or not served.api:
            raise RuntimeError(f"hexactl serve did not start:\n{served.log}")
        yield served
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        reader.join(10)


def terminate(served: Served) -> Shutdown:
    """SIGTERM, wait for the exit (killed if still running after :data:`HANG_S`), then try
    to bind each endpoint again, as a restarted service would."""
    started = time.monotonic()
    served.process.send_signal(signal.SIGTERM)
    try:
        exit_status: int | None = served.process.wait(HANG_S)
    except subprocess.TimeoutExpired:
        exit_status = None
        served.process.kill()
    seconds = time.monotonic() - started
    served.wait(HANG_S)
    return Shutdown(exit_status, seconds, tuple(endpoints_in_use(served.api, served.telemetry)))


def endpoints_in_use(*endpoints: str) -> list[str]:
    """The endpoints that cannot be bound (ZeroMQ sets SO_REUSEADDR, as the service's own
    bind does: only a listener still there counts)."""
    context = zmq.Context()
    taken = []
    try:
        for endpoint in endpoints:
            probe = context.socket(zmq.REP)
            probe.setsockopt(zmq.LINGER, 0)
            try:
                probe.bind(endpoint)
            except zmq.ZMQError:
                taken.append(endpoint)
            finally:
                probe.close()
    finally:
        context.term()
    return taken


def spawned_children(pid: int) -> list[int]:
    """The process ids of ``pid``'s children started by multiprocessing's spawn (the API
    process of a ``hexactl serve``; not multiprocessing's resource tracker), from /proc."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            try:
                if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                    found.append(int(child))
            except OSError:  # ended meanwhile
                continue
    return found


def wait_for_tool(condition: Callable[[], object], what: str, timeout_s: float = HANG_S) -> object:
    """For the benchmark tools: poll ``condition`` until it returns something true; the
    tool ends (SystemExit naming ``what``) if it does not within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if value := condition():
            return value
        time.sleep(0.1)
    raise SystemExit(f"timed out waiting for {what}")
