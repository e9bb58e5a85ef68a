"""The loop thread: runs a cycle function on absolute deadlines (the controller manager).

Timing. Deadlines are absolute, ``time.monotonic_ns`` based: deadline k = anchor + k·T,
so sleep inaccuracy never accumulates into drift. The thread sleeps until
``spin_window_us`` before the deadline (``time.sleep``: clock_nanosleep on Linux) and
busy-waits the rest, for two reasons: a sleep's wake-up is only as precise as the
scheduler's timer slack, and a thread waking from sleep must first win the GIL back,
which can take up to the GIL switch interval (see :mod:`hexactl.control.realtime`);
spinning, the loop holds the GIL when the deadline comes. After an overrun that puts the loop a whole period or more behind, it does
not burst through the missed cycles to catch up: it re-anchors the grid at the present
and counts the dropped deadlines as ``skipped`` (and as missed).

Each wake-up calls :meth:`ControlLoop.step` with the present time; tests call ``step``
directly with simulated times and never start the thread. Lateness (wake − deadline) and
compute time (wake → end of the cycle) go to :class:`~hexactl.control.stats.CycleStats`,
then to ``after_cycle`` if given (the data recorder's hook; not counted in compute).

Real-time set-up (:mod:`hexactl.control.realtime`) happens in the thread when it starts;
the young-generation garbage collection runs in a cycle's slack, and so does ``exchange``
(the service's command intake from, and snapshot publication to, its API process: see
:mod:`hexactl.application.loop_link`): after every cycle that leaves at least half a period,
and after the :data:`EXCHANGE_MAX_DEFERRED`-th cycle in a row that does not, so that an
overloaded loop still takes commands (an E-stop among them) and still reports.

If a cycle raises (a bug: the cycle code never raises by design), the thread sends an
E-stop through ``on_crash``, records the exception in :attr:`ControlLoop.failure` and
ends.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable

from hexactl.control.config import LoopConfig
from hexactl.control.realtime import RealtimeReport, apply_realtime, restore_process
from hexactl.control.stats import CycleStats

EXCHANGE_MAX_DEFERRED = 8
"""Cycles in a row without slack after which the exchange runs anyway."""


def next_deadline(deadline_ns: int, end_ns: int, period_ns: int) -> tuple[int, int]:
    """The deadline after a cycle due at ``deadline_ns`` that ended at ``end_ns``, and the
    number of deadlines dropped. Normally one period later; if that too has passed by a
    whole period or more, the grid is re-anchored at ``end_ns`` (the next cycle runs at
    once, then one per period) instead of running the missed cycles back to back."""
    following = deadline_ns + period_ns
    behind = end_ns - following
    if behind >= period_ns:
        return end_ns, behind // period_ns
    return following, 0


class ControlLoop:
    """Runs ``cycle(now_ns)`` every period, in its own thread (:meth:`start`) or when
    told (:meth:`step`). ``on_crash`` is called (from the loop thread) if ``cycle`` raises.
    :meth:`start`'s ``exchange`` runs in the thread in the cycles' slack. ``after_cycle(lateness_ns,
    compute_ns)`` follows every cycle (never raising)."""

    def __init__(self, cycle: Callable[[int], None], config: LoopConfig, on_crash: Callable[[], object],
                 after_cycle: Callable[[int, int], None] | None = None) -> None:
        self._cycle = cycle
        self._after_cycle = after_cycle
        self._on_crash = on_crash
        self._exchange: Callable[[], None] | None = None
        self.config = config
        self.period_ns = config.period_ns
        self.stats = CycleStats(self.period_ns, config.stats_window)
        self.realtime: RealtimeReport | None = None
        self.failure: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._running = False
        self._started = threading.Event()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def step(self, now_ns: int, lateness_ns: int = 0) -> None:
        """One cycle at ``now_ns`` (simulated or real); records ``lateness_ns`` and the
        cycle's compute time, measured on the real monotonic clock."""
        begin = time.monotonic_ns()
        self._cycle(now_ns)
        self._record(lateness_ns, time.monotonic_ns() - begin)

    def _record(self, lateness_ns: int, compute_ns: int) -> None:
        self.stats.record(lateness_ns, compute_ns)
        if self._after_cycle is not None:
            self._after_cycle(lateness_ns, compute_ns)

    def start(self, exchange: Callable[[], None] | None = None) -> RealtimeReport:
        """Start the thread; returns what the real-time set-up obtained. ``exchange``:
        work for the thread's slack (the link to another process), never raising."""
        if self._thread is not None:
            raise RuntimeError("the loop is already started")
        self._exchange = exchange
        self._running = True
        self._thread = threading.Thread(target=self._run, name="hexactl-control-loop", daemon=True)
        self._thread.start()
        self._started.wait()
        assert self.realtime is not None
        return self.realtime

    def stop(self, timeout_s: float = 2.0) -> None:
        """Ask the thread to finish its cycle and end; waits for it."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout_s)

    def _run(self) -> None:
        realtime = self.config.realtime
        self.realtime, previous = apply_realtime(realtime)
        self._started.set()
        period = self.period_ns
        spin_ns = round(self.config.spin_window_us * 1e3)
        gc_every_ns = round(realtime.gc_interval_s * 1e9)
        stats = self.stats
        clock = time.monotonic_ns
        exchange = self._exchange
        deferred = 0
        # ``now`` is always the clock's latest reading, never read twice: where the clock has
        # no vDSO each reading is a system call (user-mode Linux: BENCHMARKS.md has its cost).
        now = clock()
        deadline = now + period
        next_gc = deadline + gc_every_ns
        try:
            while self._running:
                remaining = deadline - now
                if remaining > spin_ns:
                    time.sleep((remaining - spin_ns) / 1e9)
                    now = clock()
                while now < deadline:
                    now = clock()
                begin = now
                self._cycle(begin)
                end = now = clock()
                self._record(begin - deadline, end - begin)
                deadline, dropped = next_deadline(deadline, end, period)
                if dropped:
                    stats.skipped += dropped
                    stats.missed += dropped
                elif realtime.manage_gc and end >= next_gc and deadline - end > period // 2:
                    gc.collect(1)
                    now = clock()
                    stats.record_gc(now - end)
                    next_gc = end + gc_every_ns
                if exchange is not None:
                    if deadline - now > period // 2 or deferred >= EXCHANGE_MAX_DEFERRED:
                        begin = now
                        exchange()
                        now = clock()
                        stats.record_exchange(now - begin)
                        deferred = 0
                    else:
                        deferred += 1
        except BaseException as error:  # noqa: BLE001 - the loop must never die silently
            self.failure = error
            self._on_crash()
        finally:
            self._running = False
            restore_process(realtime, previous)
