"""Run the vcan-marked tests inside user-mode Linux (tools/uml_vcan.py).

This host has no CAN in its kernel, so the vcan tests are deselected here
(tests/conftest.py) and this test boots UML and runs them there instead.  It is
deselected where vcan0 exists (the vcan tests then run directly) and inside the
guest.  It never skips: if UML cannot run, it fails with the reason.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.uml_runner

REPO = Path(__file__).resolve().parent.parent
TOOL = REPO / "tools" / "uml_vcan.py"
UML_TIMEOUT = int(os.environ.get("HEXACTL_UML_TIMEOUT", "1500"))
# extra room for a first-run apt-get install of user-mode-linux/kmod/iproute2
HOST_TIMEOUT = UML_TIMEOUT + 600

# '=== 4 passed, 2 deselected in 3.1s ===', or without the '=' under -q
SUMMARY = re.compile(r"^(?:=+ )?(?P<body>(?:\d+ \w+|no tests ran)(?:, \d+ \w+)* in [\d.]+s\b.*?)(?: =+)?$")
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def inner_counts(stdout: str) -> dict[str, int]:
    """Counts from the last pytest summary line, e.g. '=== 4 passed in 1.2s ==='."""
    lines = [m.group("body") for line in ANSI.sub("", stdout).splitlines()
             if (m := SUMMARY.match(line.strip()))]
    assert lines, "no pytest summary line in the inner output"
    counts = {}
    for n, word in re.findall(r"(\d+) (\w+)", lines[-1]):
        counts[word.rstrip("s") if word in ("errors", "warnings") else word] = int(n)
    return counts


def test_vcan_tests_pass_inside_uml():
    cmd = [sys.executable, str(TOOL), "--timeout", str(UML_TIMEOUT), str(REPO / "tests")]
    try:
        r = subprocess.run(cmd, cwd=REPO, stdin=subprocess.DEVNULL, capture_output=True,
                           text=True, timeout=HOST_TIMEOUT)
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"tools/uml_vcan.py did not finish in {HOST_TIMEOUT} s\n"
                    f"--- stdout ---\n{e.stdout}\n--- stderr ---\n{e.stderr}")
    report = f"exit code {r.returncode}\n--- inner output ---\n{r.stdout}\n--- tool/UML log ---\n{r.stderr}"
    print(report)  # shown by pytest on failure
    assert r.returncode == 0, report
    counts = inner_counts(r.stdout)
    assert counts.get("passed", 0) >= 1, f"inner run executed no test: {counts}\n{report}"
    assert counts.get("failed", 0) == 0 and counts.get("error", 0) == 0, f"{counts}\n{report}"
