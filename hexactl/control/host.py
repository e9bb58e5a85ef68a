"""Where the loop runs, as the :class:`~hexactl.control.controller.Controller` facade sees it.

ros2_control keeps the controller manager apart from whoever commands it; here the
facade (validation, planning, results) talks to the loop only through a
:class:`LoopHost`: the latest :class:`~hexactl.control.core.CoreSnapshot`, a way to queue a
command, and the loop's health. Two hosts:

- :class:`LoopThread` — the core and its real-time thread in this process (the service's
  own, and every test that steps the loop by hand in simulated time);
- :class:`hexactl.application.loop_link.RemoteLoop` — a loop in another process, seen
  through its published :class:`LoopReport`\\ s: the service's API process plans there, so
  its work never holds the loop's GIL.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.core import ControlCore, CoreSnapshot
from hexactl.control.hardware import ActuatorInterface, EstopCause
from hexactl.control.loop import ControlLoop
from hexactl.control.planning import ActiveGeometry
from hexactl.control.realtime import RealtimeReport
from hexactl.control.recorder import Row
from hexactl.control.stats import LoopStats


@dataclass(frozen=True, slots=True)
class LoopReport:
    """What a loop looks like from outside: its latest snapshot, timing statistics
    (percentiles at most a quarter of a second old), what its real-time set-up obtained
    (None before the thread starts), why it died (None while healthy), and the data
    recorder's rows taken since the report before (:mod:`~hexactl.control.recorder`)."""

    snapshot: CoreSnapshot
    stats: LoopStats
    realtime: RealtimeReport | None
    running: bool
    failure: str | None
    recorded: tuple[Row, ...] = ()


class LoopHost(Protocol):
    """The facade's view of a loop. ``submit`` never blocks on the loop; the loop's
    verdict appears in a later snapshot's ``outcomes``."""

    @property
    def snapshot(self) -> CoreSnapshot:
        """The loop's latest snapshot."""
        ...

    def report(self, stats_max_age_s: float) -> LoopReport:
        """The loop's latest state; percentiles recomputed if older than ``stats_max_age_s``."""
        ...

    def submit(self, command: cmd.Command) -> bool:
        """Queue ``command`` for the loop's next cycles; False if it was dropped instead
        (only a command the next one replaces, :attr:`~hexactl.control.commands.Command.superseded`,
        or a link to the loop that is gone)."""
        ...

    def estop_now(self) -> bool | None:
        """Send the E-stop to the actuators from the calling thread, ahead of the queued
        command: True if sent, False if the send failed, None if only the loop can (then
        the queued command does it within a cycle)."""
        ...

    def take_recorded(self) -> list[Row]:
        """The data recorder's rows not taken yet, oldest first (one taker per host)."""
        ...


class LoopThread:
    """The control core and its loop thread in this process (a :class:`LoopHost`).

    Construction runs one cycle at ``clock_ns()``, so the snapshot exists and the
    commanded pose starts where the actuators are. Work for the loop thread's slack is
    given when it starts (:meth:`~hexactl.control.loop.ControlLoop.start`).
    """

    def __init__(self, hardware: ActuatorInterface, active: ActiveGeometry, config: ControllerConfig,
                 clock_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.hardware = hardware
        self.core = ControlCore(hardware, active, config)
        self.loop = ControlLoop(self.core.step, config.loop,
                                on_crash=lambda: hardware.send_estop(EstopCause.CONTROLLER_FAULT),
                                after_cycle=self.core.after_cycle)
        self.core.step(clock_ns())

    @property
    def snapshot(self) -> CoreSnapshot:
        snapshot = self.core.snapshot
        assert snapshot is not None  # the constructor ran one cycle
        return snapshot

    def report(self, stats_max_age_s: float) -> LoopReport:
        failure = self.loop.failure
        return LoopReport(self.snapshot, self.loop.stats.summary(stats_max_age_s), self.loop.realtime,
                          self.loop.running, repr(failure) if failure is not None else None)

    def submit(self, command: cmd.Command) -> bool:
        # deque.append is atomic in CPython: no lock the loop could wait on.
        self.core.inbox.append(command)
        return True

    def estop_now(self) -> bool:
        return self.hardware.send_estop(EstopCause.OPERATOR)

    def take_recorded(self, limit: int = 1 << 20) -> list[Row]:
        """At most ``limit`` of the recorder's rows waiting, oldest first."""
        return self.core.recorder.take(limit)
