"""tools/bench_jog.py plans jogs in every direction and reports each case's latency."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_jog.py"


def test_every_case_is_measured() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--repeats", "2"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    rows = dict((case, [float(v) for v in values.split()])
                for case, values in re.findall(r"^(\w[\w ,-]+?)\s{2,}([0-9. ]+)$", result.stdout, re.M))
    expected = {f"{limits}, {kind}" for limits in ("no soft limits", "soft limits") for kind in ("start", "renewal", "re-plan")}
    assert set(rows) == expected, result.stdout
    for median, p90, largest in rows.values():
        assert 0 < median <= largest and p90 <= largest
