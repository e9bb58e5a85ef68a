"""A signal that lands while :class:`Spawned` starts its child: ``hexactl serve``'s
handler kills the children multiprocessing knows and exits. Landing between the child's
spawning and its start-up data, it left the child unknown, to die on the data's end with
``EOFError: Ran out of input`` and a traceback on the shared stderr (seen once in
``test_serve_ends_quietly_on_a_signal_whenever_it_lands``). Held, it runs once the child
is known."""

from __future__ import annotations

import multiprocessing
import os
import signal
from multiprocessing.connection import Connection

from hexactl.application.spawned import Spawned, signals_held


def serve_nothing(control: Connection) -> None:
    control.send({"served": True})
    control.recv()


def test_a_signal_inside_the_hold_is_handled_after_it() -> None:
    handled: list[str] = []
    previous = signal.signal(signal.SIGTERM, lambda number, frame: handled.append("handled"))
    try:
        with signals_held():
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # bytecodes at which Python would run a handler
                pass
            handled.append("end of the hold")
        assert handled == ["end of the hold", "handled"]
        assert signal.getsignal(signal.SIGTERM) is not None and signal.getsignal(signal.SIGTERM) != signal.SIG_DFL
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_signal_during_a_childs_start_is_handled_once_the_child_is_known(monkeypatch) -> None:
    start = multiprocessing.get_context("spawn").Process.start
    known_when_handled: list[list[str]] = []

    def start_then_signalled(process: multiprocessing.process.BaseProcess) -> None:
        os.kill(os.getpid(), signal.SIGTERM)  # its handler would run at the next bytecode: before the spawn
        start(process)

    def handler(number: int, frame: object) -> None:
        known_when_handled.append([child.name for child in multiprocessing.active_children()])

    monkeypatch.setattr(multiprocessing.get_context("spawn").Process, "start", start_then_signalled)
    previous = signal.signal(signal.SIGTERM, handler)
    try:
        spawned = Spawned(serve_nothing, (), name="held-start", daemon=True, start_timeout_s=120.0)
        spawned.close(10.0)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert known_when_handled == [["held-start"]]
