"""tools/bench_supervisor.py times the supervision's per-cycle call, here and in another tree."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "bench_supervisor.py"


def test_it_reports_microseconds_per_call_for_each_tree() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--calls", "200", "--repeats", "2", "--tree", str(ROOT)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert re.fullmatch(rf"{re.escape(str(ROOT))}: (\d+\.\d\d) µs per faults\(\)\n", result.stdout), result.stdout
    assert float(result.stdout.split(": ")[1].split()[0]) > 0


def test_a_tree_that_is_no_checkout_is_refused(tmp_path) -> None:
    # Its hexactl would come from wherever else the path leads (an editable install), labelled as this tree.
    result = subprocess.run([sys.executable, str(TOOL), "--calls", "200", "--tree", str(tmp_path)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and result.stdout == ""
    assert f"{tmp_path}: no hexactl package there" in result.stderr, result.stderr
