"""Loop timing statistics: fixed-size rings written on the hot path, percentiles
computed on demand in the reader's thread.

The loop records, per cycle, its wake-up lateness (actual wake − deadline) and its
compute time (wake → end of the cycle's work), both in ns, into preallocated
``array('q')`` rings: recording allocates nothing and the memory never grows.
Percentiles cover the last ``window`` cycles; maxima and counters cover the whole run.
"""

from __future__ import annotations

import time
from array import array
from dataclasses import dataclass

import numpy as np

DEFAULT_WINDOW = 16384
"""Cycles kept for percentiles: about 33 s at 500 Hz, 16 s at 1 kHz."""


@dataclass(frozen=True, slots=True)
class Percentiles:
    """Distribution summary in µs: p50, p99, p99.9 over the window, max over the run."""

    p50: float
    p99: float
    p999: float
    max: float


@dataclass(frozen=True, slots=True)
class LoopStats:
    """What the loop's timing looks like.

    ``missed``: cycles that woke more than half a period late. ``skipped``: deadlines
    dropped by re-anchoring after an overrun (the loop never bursts to catch up).
    ``gc_runs``/``gc_max_us``: young-generation collections run in the loop's slack.
    ``exchange_max_us``: the longest exchange with the API process in the loop's slack
    (0 without one).
    ``guard_clamps``: cycles in which the set-point guard had to change a set-point (a
    plan was wrong: should stay 0); ``fk_failures``: cycles whose feedback had no
    forward-kinematics solution. The controller fills these two from the cycle's state.
    ``report_age_s``: how old the report carrying these was when read, s: 0 in the loop's
    own process; read in another, the time since the loop's last report arrived there.
    """

    rate_hz: float
    cycles: int
    missed: int
    skipped: int
    lateness_us: Percentiles
    compute_us: Percentiles
    gc_runs: int
    gc_max_us: float
    exchange_max_us: float = 0.0
    guard_clamps: int = 0
    fk_failures: int = 0
    report_age_s: float = 0.0


class CycleStats:
    """The loop's counters and rings. :meth:`record` is the hot-path part; everything
    else runs in whichever thread asks."""

    def __init__(self, period_ns: int, window: int = DEFAULT_WINDOW) -> None:
        if window < 1:
            raise ValueError("window must be at least 1")
        self.period_ns = period_ns
        self.window = window
        self.cycles = 0
        self.missed = 0
        self.skipped = 0
        self.gc_runs = 0
        self.gc_max_ns = 0
        self.exchange_max_ns = 0
        self.max_lateness_ns = 0
        self.max_compute_ns = 0
        self._late_limit_ns = period_ns // 2
        self._lateness = array("q", bytes(8 * window))
        self._compute = array("q", bytes(8 * window))
        self._next = 0
        self._sorted: tuple[float, tuple[float, ...], tuple[float, ...]] | None = None  # (time, lateness, compute)

    def record(self, lateness_ns: int, compute_ns: int) -> None:
        """Store one cycle's figures (ns). Hot path: no allocation beyond int objects."""
        i = self._next
        self._lateness[i] = lateness_ns
        self._compute[i] = compute_ns
        self._next = i + 1 if i + 1 < self.window else 0
        self.cycles += 1
        if lateness_ns > self._late_limit_ns:
            self.missed += 1
        if lateness_ns > self.max_lateness_ns:
            self.max_lateness_ns = lateness_ns
        if compute_ns > self.max_compute_ns:
            self.max_compute_ns = compute_ns

    def record_gc(self, duration_ns: int) -> None:
        self.gc_runs += 1
        if duration_ns > self.gc_max_ns:
            self.gc_max_ns = duration_ns

    def record_exchange(self, duration_ns: int) -> None:
        if duration_ns > self.exchange_max_ns:
            self.exchange_max_ns = duration_ns

    def summary(self, max_age_s: float = 0.0) -> LoopStats:
        """Counters and maxima as of now; percentiles over the window, recomputed only if
        the last ones are older than ``max_age_s`` (sorting the window takes about half
        a millisecond of a thread that shares the GIL with the loop). Off the hot path."""
        now = time.monotonic()
        cached = self._sorted
        if cached is None or now - cached[0] > max_age_s:
            count = min(self.cycles, self.window)
            cached = self._sorted = (now, _percentiles(self._lateness, count), _percentiles(self._compute, count))
        _, lateness, compute = cached
        return LoopStats(
            rate_hz=1e9 / self.period_ns,
            cycles=self.cycles,
            missed=self.missed,
            skipped=self.skipped,
            lateness_us=Percentiles(*lateness, self.max_lateness_ns / 1e3),
            compute_us=Percentiles(*compute, self.max_compute_ns / 1e3),
            gc_runs=self.gc_runs,
            gc_max_us=self.gc_max_ns / 1e3,
            exchange_max_us=self.exchange_max_ns / 1e3,
        )


def _percentiles(ring: array, count: int) -> tuple[float, float, float]:
    """p50, p99, p99.9 of the first ``count`` samples, µs."""
    if count == 0:
        return 0.0, 0.0, 0.0
    # One sort of a copy (the loop keeps writing meanwhile) and three look-ups: a fraction of
    # np.percentile's time, all of which holds the GIL the loop needs.
    samples = np.sort(np.frombuffer(ring, dtype=np.int64)[:count])
    p50, p99, p999 = (_interpolated(samples, q) / 1e3 for q in (0.5, 0.99, 0.999))
    return p50, p99, p999


def _interpolated(ordered: np.ndarray, q: float) -> float:
    """The q-quantile of sorted samples, interpolated between ranks as np.percentile does."""
    position = q * (len(ordered) - 1)
    below = int(position)
    above = min(below + 1, len(ordered) - 1)
    return float(ordered[below] + (position - below) * (ordered[above] - ordered[below]))
