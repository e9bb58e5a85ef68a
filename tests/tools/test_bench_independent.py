"""tools/bench_independent.py: campaigns hexactl did not plan, calibrated and scored against the truth."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_independent.py"
sys.path.insert(0, str(TOOL.parent))

import bench_independent  # noqa: E402  (a script, imported from its folder)


def test_a_random_leg_lock_campaign_keeps_each_leg_locked_and_inside_the_limits() -> None:
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.kinematics.inverse import sensor_setpoints
    from hexactl.kinematics.pose import relative_from_absolute
    from hexactl.kinematics.workspace import assess_poses

    nominal = load_geometry(bench_independent.NOMINAL_PATH)
    rows = bench_independent.random_postures(nominal, 3, np.random.default_rng(0))
    assert [leg for leg, _, _ in rows] == [leg for leg in range(1, 7) for _ in range(3)]
    for leg, pose, reading in rows:
        assert abs(sensor_setpoints(nominal.legs, pose)[leg - 1] - reading) < 1e-6  # the locked leg keeps its reading
        assert assess_poses(nominal, [relative_from_absolute(nominal.home, pose)])[0].ok


def test_the_table_has_a_row_per_scenario_with_the_bound_and_the_ratio() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--seeds", "1", "--scenarios", "baseline", "sensor gains 5e-4"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    rows = [line.split("|")[1:-1] for line in result.stdout.splitlines() if line.startswith("| ") and "---" not in line]
    assert [row[0].strip() for row in rows[1:]] == ["baseline", "sensor gains 5e-4"]
    for row in rows[1:]:
        mean, worst = (float(v) for v in row[1].split("/"))
        predicted, bound, ratio = float(row[2]), float(row[3]), float(row[4].split()[0])
        assert 0 < mean <= worst and 0 < bound <= 1.5 * predicted
        assert 0.3 < ratio < 3.0  # where the model holds, the prediction is of the error's size
    assert "gains" in rows[2][5]  # auto identified them
