"""tools/bench_cycle_cpu.py runs each scenario and reports a figure per cycle."""

from __future__ import annotations

import cProfile
import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[2] / "tools" / "bench_cycle_cpu.py"


def run(*arguments: str) -> str:
    result = subprocess.run([sys.executable, str(TOOL), *arguments], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_cpu_time_per_cycle_for_each_scenario():
    out = run("--rounds", "2", "--cycles", "200")
    for scenario in ("disabled", "frames", "lock", "move", "turns", "recording", "wave", "wave_tool", "stream"):
        match = re.search(rf"^{scenario}: CPU per cycle min ([0-9.]+) µs, median ([0-9.]+) µs", out, re.M)
        assert match and 0 < float(match[1]) <= float(match[2]), out


def test_calls_per_cycle_are_counted_and_the_same_every_time():
    first, second = run("--calls", "--cycles", "300"), run("--calls", "--cycles", "300")
    assert first == second, (first, second)  # deterministic: what makes it a load-independent figure
    counts = dict(re.findall(r"^(\w+): ([0-9.]+) Python calls per cycle", first, re.M))
    assert set(counts) == {"disabled", "frames", "lock", "move", "turns", "recording", "wave", "wave_tool", "stream"}, \
        first
    assert float(counts["lock"]) > float(counts["move"]) > float(counts["disabled"]) > 50, first  # no motion: least
    assert float(counts["frames"]) > float(counts["turns"]), first  # the same moves, mapped through the frames
    assert float(counts["recording"]) > float(counts["turns"]), first  # the same moves, each cycle recorded
    assert float(counts["wave_tool"]) > float(counts["wave"]), first  # composed on the tool's axes every cycle


def test_bad_arguments_are_refused():
    result = subprocess.run([sys.executable, str(TOOL), "--rounds", "0"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--rounds and --cycles must be at least 1" in result.stderr


def test_calls_of_code_that_shares_a_name_are_each_counted():
    """Two dataclasses' generated ``__init__`` share the name ("<string>", 2, "__init__"), under
    which ``pstats`` keeps one: the count would then depend on which, by memory layout."""
    spec = importlib.util.spec_from_file_location("bench_cycle_cpu", TOOL)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)

    @dataclasses.dataclass
    class Once:
        value: int

    @dataclasses.dataclass
    class Thrice:
        value: int

    def build() -> None:
        Once(1)
        for value in range(3):
            Thrice(value)

    profile = cProfile.Profile()
    profile.runcall(build)
    assert tool.calls_profiled(profile) == 1 + 1 + 3 + 1  # build, the four __init__, the profiler's disable
