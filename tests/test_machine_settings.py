"""The suite passes on a machine whose operator has set hexactl up (README, "Command line"):
its geometry ($HEXACTL_CONFIG), its service's endpoints ($HEXACTL_API, a client file) are
not the tests' (tests/conftest.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tools.serving import unserved_endpoint

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 600.0  # only turns a hang into a failure


def test_the_operators_geometry_and_endpoints_do_not_reach_the_tests(tmp_path: Path) -> None:
    operators = tmp_path / "platform.toml"  # a calibrated platform: other zero lengths
    operators.write_text((ROOT / "config" / "platform.toml").read_text().replace(
        "zero_lengths = [1750.0, 1750.0, 1750.0, 1750.0, 1750.0, 1750.0]",
        "zero_lengths = [1752.0, 1752.0, 1752.0, 1752.0, 1752.0, 1752.0]"))
    assert operators.read_text() != (ROOT / "config" / "platform.toml").read_text()
    elsewhere = unserved_endpoint()
    (tmp_path / "xdg" / "hexactl").mkdir(parents=True)
    (tmp_path / "xdg" / "hexactl" / "client.toml").write_text(f'api = "{elsewhere}"\ntelemetry = "{elsewhere}"\n')
    machine = {**os.environ, "HEXACTL_CONFIG": str(operators), "HEXACTL_API": elsewhere,
               "HEXACTL_TELEMETRY": elsewhere, "XDG_CONFIG_HOME": str(tmp_path / "xdg"), "PYTHONPATH": str(ROOT)}
    inner = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
         "tests/kinematics/test_cli_kinematics.py::test_fk_warns_near_a_singular_configuration",  # the nominal geometry's
         "tests/cli/test_client_forgiving.py::test_without_settings_the_default_endpoint"],
        cwd=ROOT, env=machine, capture_output=True, text=True, timeout=TIMEOUT_S)
    assert inner.returncode == 0, inner.stdout + inner.stderr
