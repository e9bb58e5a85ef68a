"""tools/bench_service.py runs end to end and prints its side-by-side table (a smoke test:
no figure is checked, the machine is shared)."""

import json
import os
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "tools" / "bench_service.py"


def test_bench_service_runs_the_service_cyclictest_and_the_client(tmp_path: Path) -> None:
    # SCHED_FIFO needs root; where there is none, the normal configuration alone.
    configs = ["normal", "fifo-all"] if os.geteuid() == 0 else ["normal"]
    out = tmp_path / "runs.json"
    completed = subprocess.run([sys.executable, str(BENCH), "--seconds", "2", "--rates", "500", "1000",
                                "--configs", *configs, "--json", str(out)],
                               capture_output=True, text=True, timeout=600)  # fmt: skip
    assert completed.returncode == 0, completed.stderr
    runs = json.loads(out.read_text())["runs"]
    assert [(run["configuration"], run["rate_hz"]) for run in runs] == [(c, r) for c in configs for r in (500, 1000)]
    for run in runs:
        assert run["loop"]["cycles"] > 0 and run["cyclictest"]["cycles"] > 0
        assert run["client"]["answered"] > 0 and run["client"]["telemetry_records"] > 0
    for row in ("lateness p99 µs: loop / cyclictest", "API sent / answered / errors", "missed ≤ 0.1 % at 500 Hz",
                "p99 lateness ≤ cyclictest p99 + 100 µs", "compute p99 ≤ 10 % of the period", "load average"):
        assert row in completed.stdout, completed.stdout
