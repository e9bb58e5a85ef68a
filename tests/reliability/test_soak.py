"""tools/soak.py for 20 seconds: sequences, calibration swaps (good and bad) and API traffic
on the real service, no limit violation on the bus, every request answered, every bad
calibration refused with its code (the loop's figures are
reported by the tool, not judged here)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_to_toml, load_geometry
from tools.soak import CalibrationSwaps, bad_calibrations

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


class RampRefusal:
    """A service refusing every ``load_calibration`` as the ramp check does near the
    envelope's edge."""

    def request(self, cmd: str, **fields: str) -> dict:
        return {"ok": False, "error": {"code": "invalid_geometry", "message": "at ramp fraction 0.50 …"}}


def test_a_far_calibration_refused_by_its_ramp_counts_as_refused() -> None:
    # While the X sweep plays near x = ±600 mm, the ramp to a zero length 40 mm off leaves
    # the envelope, which the service checks before the change's size: the refusal is then
    # invalid_geometry, and a soak with frequent swaps used to fail on it.
    nominal = load_geometry(default_config_path())
    far = [entry for entry in bad_calibrations(nominal) if 'name = "40 mm off"' in entry[0].get("toml", "")]
    swapper = CalibrationSwaps(RampRefusal(), [geometry_to_toml(nominal)], far)
    swapper.swap(Counter())  # the good variant's turn
    swapper.swap(Counter())  # the far one's
    assert (swapper.bad_sent, swapper.bad_wrong) == (1, 0)
