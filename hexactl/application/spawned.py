"""A spawned child process that serves until told to stop, on a control pipe: the
service in a process of its own (:class:`~hexactl.application.service.ServiceProcess`) and
the service's API process (:class:`~hexactl.application.api_process.ApiProcess`).

The protocol on the control pipe: the child's first message is either where it serves
(any non-string object) or, as a string, why it cannot; then it answers each request
once carried out (with the word itself, or what was asked for), and ends at :data:`STOP` or when the parent's end
closes (the parent died).

Every wait is bounded: a child that does not end when told is killed (SIGKILL: it may
ignore SIGTERM, be stopped, or be stuck in a call that never returns) and reaped, so
that neither :meth:`Spawned.close` nor multiprocessing's exit handler, which joins every
child it knows without a timeout, can hang on it.
"""

from __future__ import annotations

import logging
import multiprocessing
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from multiprocessing.connection import Connection

STOP = "stop"

KILL_REAP_TIMEOUT_S = 1.0
"""How long :meth:`Spawned.close` waits for a killed child to be gone (SIGKILL ends even
a stopped process; one in uninterruptible sleep ends when that call returns)."""

log = logging.getLogger("hexactl.spawned")


class SpawnError(RuntimeError):
    """The child did not start; the message says why."""


HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def signals_held(signals: Iterable[signal.Signals] = HELD_SIGNALS) -> Iterator[None]:
    """In the main thread: ``signals`` received inside the ``with`` are raised again as it
    ends, so that their handlers (or default actions) run after the block, not halfway
    through it. For starting a child: a handler run between its spawning and the pickled
    start-up data it waits for (``hexactl serve``'s, which kills the children it knows and
    exits) left it unknown, to die on the data's end with a traceback on the shared stderr.
    Elsewhere a no-op: Python runs signal handlers in the main thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    held = [number for number in signals if signal.getsignal(number) is not None]  # None: a handler not Python's
    previous = {number: signal.signal(number, lambda number, frame: received.append(number)) for number in held}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        for number in dict.fromkeys(received):
            signal.raise_signal(number)


class Spawned:
    """Start ``target(*args, control)`` in a spawned process named ``name`` (spawned, not
    forked: the parent has threads) and wait at most ``start_timeout_s`` for where it
    serves (:attr:`served`). ``handed_over``: pipe ends among ``args`` that are the child's
    now, closed here once it has them.

    :raises SpawnError: if the child says it cannot serve, ends, or is silent too long
    """

    def __init__(self, target: Callable[..., None], args: tuple, *, name: str, daemon: bool,
                 start_timeout_s: float, handed_over: Iterable[Connection] = ()) -> None:
        context = multiprocessing.get_context("spawn")
        self._control, child = context.Pipe()
        self._process = context.Process(target=target, args=(*args, child), name=name, daemon=daemon)
        with signals_held():
            self._process.start()
        for end in (*handed_over, child):
            end.close()
        message: object = f"{name} did not start within {start_timeout_s:g} s"
        try:
            if self._control.poll(start_timeout_s):
                message = self._control.recv()
        except (EOFError, OSError):
            message = f"{name} ended (exit status {self._process.exitcode}) before it started"
        if isinstance(message, str):
            self.close(start_timeout_s)
            raise SpawnError(message)
        self.served = message

    @property
    def pid(self) -> int | None:
        return self._process.pid

    @property
    def alive(self) -> bool:
        return self._process.is_alive()

    @property
    def exitcode(self) -> int | None:
        return self._process.exitcode

    def request(self, word: str, timeout_s: float) -> object:
        """Send ``word``; return the child's answer once it has carried it out (None if
        it is gone or silent for ``timeout_s``)."""
        try:
            self._control.send(word)
            if self._control.poll(timeout_s):
                return self._control.recv()
        except (EOFError, OSError):
            pass  # gone already
        return None

    def close(self, timeout_s: float) -> None:
        """Send :data:`STOP` and wait at most ``timeout_s`` for the child to end; kill it
        if it has not (logged). Returns within ``timeout_s`` + :data:`KILL_REAP_TIMEOUT_S`."""
        try:
            self._control.send(STOP)  # a few bytes: the pipe takes them even from a stuck child
        except OSError:
            pass  # gone already
        self._process.join(timeout_s)
        if self._process.is_alive():
            log.warning("%s (pid %s) did not end within %g s of being told to: killed", self._process.name,
                        self._process.pid, timeout_s)
            self._process.kill()
            self._process.join(KILL_REAP_TIMEOUT_S)
        self._control.close()
