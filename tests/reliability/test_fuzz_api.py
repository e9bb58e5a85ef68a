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


def test_the_code_canary_is_the_runs_own(tmp_path) -> None:
    """A calibration text asks a shell to create a file: one in the run's own directory, not
    a fixed /tmp name that one run left (or another made) for every later run to report."""
    from hexactl.adapters.files.config_path import default_config_path
    from hexactl.adapters.files.geometry_file import load_geometry
    from tools.fuzz_api import prepare_files

    files = prepare_files(tmp_path, load_geometry(default_config_path()))
    assert files["pwned"].parent == tmp_path and not files["pwned"].exists()
    assert any(f"$(touch '{files['pwned']}')" in text for text in files["hostile_texts"])


def test_a_name_too_long_to_save_may_be_refused_write_failed_and_only_such_a_name() -> None:
    """Over-long names are among the hostile writes; with a recording to save, the service
    refuses one ``write_failed`` ("give a shorter name"). The run failed under load, when
    a sequence had been recorded before that request; the outcome is allowed for such a
    name only."""
    from tools.fuzz_api import save_refusals

    assert "write_failed" in save_refusals("a" * 300 + ".csv")
    assert "write_failed" not in save_refusals("../outside/escaped.csv")
    assert "write_failed" not in save_refusals("a" * 300 + "/r.csv")  # its directory cannot be opened: file_not_found
