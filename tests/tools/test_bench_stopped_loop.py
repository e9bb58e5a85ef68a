"""tools/bench_stopped_loop.py stops a real service's loop process and times the API's
replies meanwhile."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "bench_stopped_loop.py"


def test_a_short_run_reports_every_reply_and_the_estop_carried_out() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--moves", "5"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    assert re.search(r"^moves sent: 5 of 5; replies: \{'loop_silent': 5\}$", out, re.MULTILINE), out
    assert re.search(r"^move reply: median \d+ ms, max \d+ ms$", out, re.MULTILINE), out
    assert re.search(r"^then status: ok after \d+ ms; estop: loop_silent after \d+ ms$", out, re.MULTILINE), out
    assert "the E-stop carried out once the loop ran again: yes" in out, out
