"""The shipped vehicle trajectories are what their documented script writes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[2]
TOOL = REPOSITORY / "tools" / "make_vehicle_trajectories.py"


def test_the_script_rewrites_the_shipped_files_byte_for_byte(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--out", str(tmp_path)], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    for name in ("braking.csv", "lane_change.csv"):
        assert (tmp_path / name).read_bytes() == (REPOSITORY / "config" / "vehicles" / name).read_bytes(), name
