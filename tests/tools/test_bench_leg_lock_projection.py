"""tools/bench_leg_lock_projection.py times both cases, each converged in a few iterations."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_leg_lock_projection.py"


def test_both_cases_are_timed_and_converge_in_a_few_iterations() -> None:
    result = subprocess.run([sys.executable, str(TOOL)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rows = re.findall(r"^(.+): ([0-9.]+) µs, (\d+) iterations$", result.stdout, re.M)
    assert [name for name, _, _ in rows] == ["from the last cycle's answer", "30 mm off the surface"], result.stdout
    assert all(float(micro) > 0 and 1 <= int(iterations) <= 5 for _, micro, iterations in rows)


def test_a_path_that_is_no_checkout_is_refused(tmp_path) -> None:
    # Its hexactl would come from wherever else the path leads (an editable install).
    result = subprocess.run([sys.executable, str(TOOL), str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 2 and result.stdout == ""
    assert f"{tmp_path}: no hexactl package there" in result.stderr, result.stderr
