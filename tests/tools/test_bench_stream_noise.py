"""tools/bench_stream_noise.py streams noisy poses to the controller in simulated time and
reports what was commanded."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_stream_noise.py"


def test_the_noise_and_the_sine_are_reported() -> None:
    result = subprocess.run([sys.executable, str(TOOL), "--noise", "1"], capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr
    sine = re.search(r"sine x 10 mm at 1 Hz, largest tracking error ([0-9.]+) mm", result.stdout)
    assert sine and 0 < float(sine[1]) < 1.0, result.stdout
    rows = re.findall(r"^\| ([0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \| ([0-9]+) \| ([0-9]+) \|$", result.stdout, re.M)
    assert len(rows) == 1, result.stdout
    noise, held, edge, outside, clamps = rows[0]
    assert noise == "1" and 0 < float(held) < 5.0 and 605.0 < float(edge) < 610.0, result.stdout
    assert (outside, clamps) == ("0", "0"), result.stdout
