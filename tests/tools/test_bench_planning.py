"""tools/bench_planning.py plans each long motion (every plan accepted) and reports its times."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_planning.py"


def test_every_case_is_planned_and_reported() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--repeats", "1"], capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr
    rows = re.findall(r"^\| (.+?) \| ([0-9.]+) \(([0-9.]+)\) s, ([0-9.]+) s \|$", result.stdout, re.M)
    assert [row[0].split(",")[-1].strip() for row in rows] == ["validate_wave", "validate_sequence", "validate_pose"], \
        result.stdout
    for _, least, median, cpu in rows:
        assert 0 < float(least) <= float(median) and float(cpu) > 0
