"""tools/bench_dashboard.py --flood: a page floods E-stops it never reads while fresh pages
time theirs, on a real service and dashboard; the table gives the round trips and the
dashboard's memory."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_dashboard.py"


def test_a_flood_is_sent_and_fresh_pages_e_stops_are_timed_beside_it() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--flood", "2000", "--estops", "3"], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    row = re.search(r"^\| (\d+) of 2000 \| ([0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \| (\d+) → (\d+) MB \|", result.stdout, re.M)
    assert row, result.stdout
    sent, p50, p95, most, start_mb, peak_mb = (float(value) for value in row.groups())
    assert 0 < sent <= 2000 and 0 < p50 <= p95 <= most and start_mb > 0 and peak_mb > 0
