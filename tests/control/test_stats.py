import pytest

from hexactl.control.stats import CycleStats


def test_percentiles_over_the_window_maxima_over_the_run():
    stats = CycleStats(period_ns=2_000_000, window=1000)
    stats.record(5_000_000, 900_000)  # a big one that leaves the window later
    for i in range(2000):
        stats.record(i % 1000 * 1000, 100_000)
    summary = stats.summary()
    assert summary.cycles == 2001
    assert summary.missed == 1  # only the one later than half a period
    assert summary.lateness_us.max == 5000.0
    assert summary.lateness_us.p50 == pytest.approx(499.5, abs=1)
    assert summary.lateness_us.p99 == pytest.approx(990, abs=2)
    assert summary.compute_us.p50 == 100.0 and summary.compute_us.max == 900.0
    assert summary.rate_hz == 500.0


def test_empty_summary():
    summary = CycleStats(period_ns=1_000_000).summary()
    assert summary.cycles == 0 and summary.lateness_us.p999 == 0.0


def test_percentiles_are_cached_but_counters_are_live():
    stats = CycleStats(period_ns=1_000_000, window=100)
    stats.record(100_000, 10_000)
    first = stats.summary(max_age_s=60.0)
    stats.record(900_000, 10_000)
    cached = stats.summary(max_age_s=60.0)
    assert cached.cycles == 2 and cached.missed == 1 and cached.lateness_us.max == 900.0
    assert cached.lateness_us.p50 == first.lateness_us.p50  # not recomputed yet
    assert stats.summary().lateness_us.p50 == 500.0  # max_age_s=0: fresh
