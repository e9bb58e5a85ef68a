"""tools/bench_jog_cli.py jogs through the command line on a real service and reports how far."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_jog_cli.py"


def test_a_jog_is_run_and_its_travel_reported() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--runs", "1"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    found = re.search(r"^travelled: median ([0-9.]+) mm, max ([0-9.]+) mm \(asked 10 mm\)", result.stdout, re.M)
    assert found, result.stdout
    assert 0 < float(found[1]) <= float(found[2])  # up, as asked
