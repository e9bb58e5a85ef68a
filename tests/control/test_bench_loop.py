"""tools/bench_loop.py runs end to end (a smoke test: the figures are not checked)."""

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "tools" / "bench_loop.py"


def test_bench_runs_every_scenario_and_writes_its_rows(tmp_path):
    for scenario in ("move", "lock"):
        out = tmp_path / f"{scenario}.json"
        completed = subprocess.run([sys.executable, str(BENCH), "--seconds", "0.3", "--rate", "500", "1000",
                                    "--scenario", scenario, "--json", str(out)],
                                   capture_output=True, text=True, timeout=120)
        assert completed.returncode == 0, completed.stderr
        rows = json.loads(out.read_text())
        assert [row["rate_hz"] for row in rows] == [500.0, 1000.0]
        assert all(row["cycles"] > 0 and row["guard_clamps"] == 0 for row in rows)
        assert "late_p999_us" in completed.stdout
