"""``hexactl serve`` in a process of its own, as an operator runs it: started in a working
directory on loopback ports (or the endpoints given), its log read all along, ended with
SIGTERM and checked against the promise a service manager relies on: exit status 0
within :data:`SHUTDOWN_BOUND_S`, both endpoints free to bind again.

One helper for the tests and tools that need the real command (``tools/file_race.py``,
``tests/api``, ``tests/reliability``); :func:`hexactl_process` also starts ``hexactl
dashboard`` (``tools/browser.py``), and :func:`wait_until` is their one polling wait."""

from __future__ import annotations

import functools
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

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
class Logged:
    """A ``hexactl`` command in a process of its own and its log as it grows, read all along
    by a thread (a full pipe would block the command's logging)."""

    process: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)
    reader: threading.Thread | None = None

    @property
    def log(self) -> str:
        return "".join(self.lines)


@dataclass
class Served(Logged):
    """A running ``hexactl serve``: its process, endpoints, and its log as it grows."""

    api: str = ""
    telemetry: str = ""

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


LoggedT = TypeVar("LoggedT", bound=Logged)


@contextmanager
def hexactl_process(kind: type[LoggedT], arguments: list[str], ready: re.Pattern[str], timeout_s: float, *,
                    cwd: Path | None = None, merge_stdout: bool = False,
                    sigterm_grace_s: float | None = None) -> Iterator[LoggedT]:
    """``hexactl *arguments`` in a process of its own (held by a ``kind``), once it has
    logged a line that ``ready`` matches, whose named groups set the same-named fields of
    ``kind``; its stderr is its log (with its stdout if ``merge_stdout``). On the way out,
    if still running, it is killed: at once, or when it has not exited ``sigterm_grace_s``
    after SIGTERM.

    :raises RuntimeError: if it exits, or logs no such line, within ``timeout_s``
    """
    process = subprocess.Popen(
        [sys.executable, "-m", "hexactl.adapters.cli.main", *arguments],
        stdout=subprocess.PIPE if merge_stdout else None, stderr=subprocess.STDOUT if merge_stdout else subprocess.PIPE,
        text=True, cwd=cwd, env={**os.environ, "PYTHONUNBUFFERED": "1"},
        # As from a terminal, whatever this process's own: a test run as a background job
        # ignores SIGINT, and a service started so keeps ignoring it (its parent's wish).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    logged = kind(process)
    log = process.stdout if merge_stdout else process.stderr
    started = threading.Event()
    said_ready = False

    def read() -> None:
        nonlocal said_ready
        assert log is not None
        for line in log:
            logged.lines.append(line)
            if found := ready.search(line):
                for name, value in found.groupdict().items():
                    setattr(logged, name, value)
                said_ready = True
                started.set()
        started.set()  # exited: not ready

    reader = logged.reader = threading.Thread(target=read, name=f"{arguments[0]}-log", daemon=True)
    reader.start()
    try:
        if not started.wait(timeout_s) or not said_ready:
            raise RuntimeError(f"hexactl {arguments[0]} did not start:\n{logged.log}")
        yield logged
    finally:
        if process.poll() is None and sigterm_grace_s is not None:
            process.terminate()
            try:
                process.wait(sigterm_grace_s)
            except subprocess.TimeoutExpired:
                pass
        if process.poll() is None:
            process.kill()
        process.wait()
        reader.join(10)


@contextmanager
def serve(directory: Path, *options: str, api: str = LOOPBACK, telemetry: str = LOOPBACK) -> Iterator[Served]:
    """``hexactl serve *options`` with ``directory`` as its working directory (so its data
    directories are there by default), started; killed on the way out if still running
    (:func:`terminate` is the clean end).

    :raises RuntimeError: if it exits, or does not say where it serves within
        :data:`START_TIMEOUT_S`
    """
    with hexactl_process(Served, ["serve", "--api", api, "--telemetry", telemetry, *options], _SERVING,
                         START_TIMEOUT_S, cwd=directory) as served:
        yield served


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


_UNSERVED: list[socket.socket] = []  # held for the process's life


def unserved_endpoint() -> str:
    """``tcp://127.0.0.1:PORT`` where nothing listens for as long as this process runs: a
    port it keeps bound and never listens on, so a connection there is refused at once.
    (A fixed port such as 1 is not that: a service started on it as root answered the
    tests and tools that took it for nobody's.)"""
    held = socket.socket()
    held.bind(("127.0.0.1", 0))
    _UNSERVED.append(held)
    return f"tcp://127.0.0.1:{held.getsockname()[1]}"


def free_port() -> int:
    """A TCP port on the loopback that nothing listens on now (the kernel's pick)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


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


ConditionT = TypeVar("ConditionT")


def wait_until(condition: Callable[[], ConditionT], what: str, timeout_s: float, *, poll_s: float = 0.05,
               seen: Callable[[], object] | None = None,
               failure: type[BaseException] = AssertionError) -> ConditionT:
    """The first true value ``condition()`` returns, asked every ``poll_s``; after
    ``timeout_s``, ``failure`` (AssertionError for a test, SystemExit for a tool) naming
    ``what`` and, to tell why, what ``seen()`` returns then. The bound only turns a hang
    into a failure: it asserts nothing about timing."""
    deadline = time.monotonic() + timeout_s
    while not (value := condition()):
        if time.monotonic() >= deadline:
            raise failure(f"timed out after {timeout_s:g} s waiting for {what}" + (f"; seen: {seen()}" if seen else ""))
        time.sleep(poll_s)
    return value


wait_for_tool = functools.partial(wait_until, timeout_s=HANG_S, poll_s=0.1, failure=SystemExit)
"""For the benchmark tools: :func:`wait_until` that ends the tool."""
