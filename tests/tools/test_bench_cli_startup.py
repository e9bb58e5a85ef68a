"""tools/bench_cli_startup.py refuses a tree it cannot measure (the timing itself is not tested)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_cli_startup.py"


def test_a_tree_that_is_no_checkout_is_refused(tmp_path) -> None:
    # `python3 -m hexactl…` there would import an installed hexactl, reported as this tree's.
    result = subprocess.run([sys.executable, str(TOOL), "--runs", "1", "--tree", str(tmp_path)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and result.stdout == ""
    assert f"{tmp_path}: no hexactl package there" in result.stderr, result.stderr
