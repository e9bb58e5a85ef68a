"""tools/bench_instruments.py: calibration from points, theodolite angles and tracker observations."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_instruments.py"


def test_each_instrument_has_a_row_with_a_consistent_fit() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--seeds", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    rows = {line.split("|")[1].strip(): line.split("|")[2:-1] for line in result.stdout.splitlines()
            if line.startswith("| ") and "---" not in line and "observations" not in line}
    assert set(rows) == {"points", "theodolites", "tracker"}
    for cells in rows.values():
        mean = float(cells[0].split("/")[0])
        assert 0 < mean < 0.5 and 0.7 < float(cells[2]) < 1.3  # χ²/dof
