"""tools/bench_api_silence.py freezes a real service's API process mid-move and reports what
the loop did about it."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "bench_api_silence.py"


def test_one_run_reports_the_silence_the_log_line_and_the_travel() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--runs", "1"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    run = re.search(r"^run 1: braked at (\d+\.\d) s of silence, logged (\d+\.\d\d) s after the freeze; went "
                    r"(\d+\.\d) mm after it, of (\d+\.\d) mm the move had left$", result.stdout, re.MULTILINE)
    assert run, result.stdout
    silence_s, logged_s, travel_mm, remaining_mm = map(float, run.groups())
    assert silence_s >= 1.0 and logged_s > 0 and travel_mm < remaining_mm
    assert re.search(r"^1 runs, load average \d+\.\d\d$", result.stdout, re.MULTILINE), result.stdout
