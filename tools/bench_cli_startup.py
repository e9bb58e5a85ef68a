"""Benchmark how long ``hexactl`` commands take to start: whole-process wall time.

Each command runs ``--runs`` times as a fresh ``python3 -m hexactl.adapters.cli.main``
process: ``--help``, and ``status``, ``move`` and ``events`` against an endpoint where nothing
listens with a 50 ms timeout (they fail fast: what is measured is the start-up plus that
timeout), beside a bare ``python3 -c pass`` as the anchor. With several ``--tree``
checkouts (e.g. a worktree of HEAD beside the working copy) the runs alternate between
them, so that a busy machine's load falls on all alike.

    python3 tools/bench_cli_startup.py                                   # this checkout, 10 runs
    python3 tools/bench_cli_startup.py --tree /work/before_cli --tree . --importtime 15

Prints a markdown table of min and median wall time per command and tree, and with
``--importtime N`` the N imports of ``hexactl.adapters.cli.main`` with the largest
cumulative time (``python3 -X importtime``), per tree.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

NO_SERVICE = ["--api", "tcp://127.0.0.1:1", "--timeout", "0.05"]
CLI = [sys.executable, "-m", "hexactl.adapters.cli.main"]
COMMANDS: dict[str, list[str]] = {
    "python3 -c pass": [sys.executable, "-c", "pass"],
    "hexactl --help": [*CLI, "--help"],
    "hexactl status": [*CLI, "status", *NO_SERVICE],
    "hexactl move": [*CLI, "move", "0,0,0,0,0,0", *NO_SERVICE],
    "hexactl events": [*CLI, "events", *NO_SERVICE],
}
EXPECTED_STATUS = {"python3 -c pass": 0, "hexactl --help": 0, "hexactl status": 2, "hexactl move": 2,
                   "hexactl events": 2}
"""``status``, ``move`` and ``events`` find no service: exit 2 (no answer); anything else is a broken run."""


def environment(tree: Path) -> dict[str, str]:
    """This process's environment with ``tree`` first on the module path."""
    return {**os.environ, "PYTHONPATH": str(tree)}


def run_once(command: list[str], tree: Path) -> tuple[float, int]:
    """Wall time (s) and exit status of one run of ``command`` on ``tree``'s code (run in
    ``tree``: ``python3 -m`` puts the working directory first on the module path)."""
    start = time.perf_counter()
    status = subprocess.run(command, cwd=tree, env=environment(tree), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL).returncode
    return time.perf_counter() - start, status


def import_times(tree: Path, count: int) -> list[str]:
    """The ``count`` imports of the CLI with the largest cumulative time, slowest last."""
    result = subprocess.run([sys.executable, "-X", "importtime", "-c", "import hexactl.adapters.cli.main"],
                            cwd=tree, env=environment(tree), capture_output=True, text=True, check=True)
    rows = [line for line in result.stderr.splitlines() if line.startswith("import time:") and "cumulative" not in line]
    return sorted(rows, key=lambda line: int(line.split("|")[1]))[-count:]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10, help="runs of each command per tree (default 10)")
    parser.add_argument("--tree", action="append", type=Path, metavar="DIR",
                        help="checkout whose code to run (repeatable; default: this one)")
    parser.add_argument("--importtime", type=int, default=0, metavar="N", help="also list the N slowest imports")
    arguments = parser.parse_args(argv)
    trees = [tree.resolve() for tree in arguments.tree or [Path(__file__).resolve().parent.parent]]
    for tree in trees:
        if not (tree / "hexactl" / "__init__.py").is_file():  # else an installed hexactl would be measured instead
            parser.error(f"{tree}: no hexactl package there: give the root of a checkout (e.g. made by git worktree add)")

    times: dict[tuple[Path, str], list[float]] = {(tree, name): [] for tree in trees for name in COMMANDS}
    for _ in range(arguments.runs):
        for name, command in COMMANDS.items():
            for tree in trees:
                seconds, status = run_once(command, tree)
                if status != EXPECTED_STATUS[name]:
                    print(f"{name} on {tree}: exit status {status}, expected {EXPECTED_STATUS[name]}", file=sys.stderr)
                    return 1
                times[tree, name].append(seconds)

    print(f"{arguments.runs} runs each, load average {os.getloadavg()[0]:.1f} at the end\n")
    print("| tree | command | min s | median s |")
    print("|---|---|---:|---:|")
    for tree in trees:
        for name in COMMANDS:
            values = times[tree, name]
            print(f"| {tree} | {name} | {min(values):.3f} | {statistics.median(values):.3f} |")
    for tree in trees if arguments.importtime else ():
        print(f"\n`python3 -X importtime -c 'import hexactl.adapters.cli.main'` on {tree}, slowest {arguments.importtime} "
              "(self µs | cumulative µs | module):\n")
        for line in import_times(tree, arguments.importtime):
            print(f"    {line.removeprefix('import time:').strip()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
