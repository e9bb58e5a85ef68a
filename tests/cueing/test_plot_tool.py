"""tools/plot_cueing.py draws both manoeuvres' figures."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "plot_cueing.py"


def test_both_figures_are_drawn(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--out", str(tmp_path)], capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, result.stderr
    for name in ("cueing-braking.png", "cueing-lane-change.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
