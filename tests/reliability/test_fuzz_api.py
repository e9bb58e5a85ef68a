"""tools/fuzz_api.py, CI-sized: 500 hostile requests against the real service on its
simulator, enabled, with a bus monitor on its bus. Every request answered once, with an
outcome its category allows; no set-point beyond the limits on the bus; still serving."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "fuzz_api.py"
COUNT = 500


def test_500_hostile_requests(tmp_path) -> None:
    out = tmp_path / "fuzz.json"
    completed = subprocess.run([sys.executable, str(TOOL), "--count", str(COUNT), "--seed", "1", "--json", str(out)],
                               capture_output=True, text=True, timeout=600)
    result = json.loads(out.read_text())
    assert result["requests"] == COUNT
    assert result["unexpected_examples"] == [] and result["unexpected"] == 0, completed.stdout
    assert (result["replies_missing"], result["extra_replies"]) == (0, 0)
    assert result["still_serving"] and not result["code_executed"] and result["files_escaped"] == []
    assert result["monitor"]["violations"] == 0, result["monitor"]["first_violations"]
    assert result["monitor"]["counts"]["setpoints"] > 0  # it watched the platform being driven
    assert sum(result["by_category"].get("valid", {}).values()) > 0 and result["by_outcome"].get("ok", 0) > 0
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "replies missing: 0" in completed.stdout
