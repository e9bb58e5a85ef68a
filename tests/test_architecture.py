"""The layers that README.md and docs/architecture.md state, checked by import-linter
(``pyproject.toml``, ``[tool.importlinter]``): the tree keeps every contract, and each kind
of wrong-way import breaks the check (so the check can fail).

Each check runs ``lint-imports`` in a process of its own, on the tree given by its
``PYTHONPATH``: the copies below are found before the installed package."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 300.0  # only turns a hang into a failure


def lint_imports(tree: Path) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` with ``tree``'s pyproject.toml on the ``hexactl`` package in ``tree``."""
    code = ("import sys; from importlinter.cli import lint_imports; "
            "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")
    return subprocess.run([sys.executable, "-c", code], cwd=tree, capture_output=True, text=True, timeout=TIMEOUT_S,
                          env={**os.environ, "PYTHONPATH": str(tree)})


def test_the_tree_keeps_every_contract() -> None:
    result = lint_imports(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "3 kept, 0 broken" in result.stdout, result.stdout


@pytest.mark.parametrize(("module", "wrong_import", "contract"), [
    ("kinematics/geometry.py", "import hexactl.control.planning", "Layers"),
    ("control/guard.py", "import hexactl.adapters.can.link", "Layers"),
    ("adapters/can/link.py", "import hexactl.application.service", "Layers"),
    ("application/spawned.py", "import hexactl.adapters.cli.main", "Layers"),
    ("calibration/parameters.py", "import json", "The pure math"),
    ("control/trajectory.py", "import zmq", "The control loop knows no wire or file format"),
], ids=["math->control", "control->adapter", "adapter->application", "application->cli", "math->json",
        "control->zmq"])
def test_a_wrong_way_import_breaks_the_check(tmp_path: Path, module: str, wrong_import: str, contract: str) -> None:
    shutil.copytree(ROOT / "hexactl", tmp_path / "hexactl", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    target = tmp_path / "hexactl" / module
    target.write_text(target.read_text() + f"\n{wrong_import}  # the wrong way\n")
    result = lint_imports(tmp_path)
    assert result.returncode != 0, result.stdout
    text = " ".join(result.stdout.split())  # contract names wrap
    assert re.search(re.escape(contract) + r"(?:(?!KEPT|BROKEN).)*BROKEN", text), result.stdout
