"""tools/bench_dashboard.py --silent: connections that send nothing are held open beside a
real service and dashboard while fresh pages time their E-stop; the table gives the
round trips, the dashboard's descriptors and how many of the silent connections it kept
(at most GuardedH11Protocol's bound)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from hexactl.adapters.web.connections import GuardedH11Protocol

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_dashboard.py"


def test_silent_connections_are_held_and_fresh_pages_e_stops_are_timed_beside_them() -> None:
    silent = GuardedH11Protocol.max_awaiting_head + 100
    result = subprocess.run([sys.executable, str(TOOL), "--silent", str(silent), "--estops", "3"], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    row = re.search(rf"^\| {silent} \((\d+)\) \| (\d+), (\d+), (\d+) \| ([0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \| 0 \| 0 \|",
                    result.stdout, re.M)
    assert row, result.stdout
    kept, before, opened, after, p50, p95, most = (float(value) for value in row.groups())
    assert kept <= GuardedH11Protocol.max_awaiting_head
    assert 0 < before <= opened and 0 < after and 0 < p50 <= p95 <= most
