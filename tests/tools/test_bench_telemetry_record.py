"""tools/bench_telemetry_record.py measures a record as a working service publishes it:
with the loop's events window full, and the figures it prints are the ones it writes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_telemetry_record.py"


def test_a_record_with_its_events_is_measured_and_reported(tmp_path: Path) -> None:
    out = tmp_path / "record.json"
    result = subprocess.run([sys.executable, str(TOOL), "--records", "20", "--runs", "2", "--json", str(out)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    figures = json.loads(out.read_text())
    assert figures["events_in_record"] == 8  # more events happened than a record carries
    assert figures["bytes"] > 1000 and 0 < figures["least_us"] <= figures["median_us"]
    assert f"record: {figures['bytes']} bytes, 8 events" in result.stdout
