"""tools/soak.py for 20 seconds: sequences, calibration swaps (good and bad) and API traffic
on the real service, no limit violation on the bus, every request answered, every bad
calibration refused with its code (the loop's figures are
reported by the tool, not judged here)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "soak.py"


def test_20_second_soak(tmp_path) -> None:
    out = tmp_path / "soak.json"
    completed = subprocess.run([sys.executable, str(TOOL), "--seconds", "20", "--swap-every", "2", "--json", str(out)],
                               capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    result = json.loads(out.read_text())
    assert result["monitor"]["violations"] == 0 and result["monitor"]["counts"]["setpoints"] > 0
    assert (result["requests_missing"], result["internal_errors"]) == (0, 0)
    assert result["sequences_played"] >= 1 and result["calibration_swaps"] >= 2
    assert result["bad_calibrations_sent"] >= 2 and result["bad_calibrations_not_refused_as_expected"] == 0
    assert result["requests"].get("status:ok", 0) > 0 and result["telemetry_records"] > 0
    assert result["loop"]["cycles"] > 0 and result["loop"]["guard_clamps"] == 0
