"""``hexactl plot`` of a long recording: its wall time and peak memory (the child process's
maximum resident set, ``ru_maxrss``), for a recording of every signal, ROWS rows at 500 Hz
(the recorder's own columns: ``hexactl.adapters.files.recording_file.columns``), written
once to a temporary folder:

    python3 tools/bench_plot.py                         # 200,000 rows (400 s)
    python3 tools/bench_plot.py --rows 1800000          # the longest recording: 1 h at 500 Hz
    python3 tools/bench_plot.py --tree /tmp/base --tree .

With several ``--tree`` checkouts (each one's ``hexactl`` run, e.g. a ``git worktree`` of the
revision before a change), each plots the same file in a process of its own.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 500


def write_recording(path: Path, rows: int) -> None:
    """A recording of every signal: slow sines, a lateness spike every 10,000 rows."""
    sys.path.insert(0, str(ROOT))
    from hexactl.adapters.files.recording_file import SIGNALS, columns

    header = [name for name, _ in columns(SIGNALS)]
    signals = len(header) - 2
    with path.open("w", encoding="utf-8") as file:
        file.write(",".join(header) + "\n")
        for n in range(rows):
            t = n / RATE_HZ
            wave = f"{10 * math.sin(t):.4f}"
            cells = [wave] * (signals - 2) + ["900" if n % 10_000 == 0 else "12", "150"]
            file.write(f"{t:.6f},{n}," + ",".join(cells) + "\n")


def plot(tree: Path, recording: Path) -> dict:
    """Plot ``recording`` with ``tree``'s hexactl in a child process: wall s, peak MiB."""
    image = recording.with_name(f"{recording.stem}-{os.getpid()}-{abs(hash(str(tree)))}.png")
    program = ("import sys\nfrom hexactl.adapters.cli.main import main\n"
               f"sys.exit(main(['plot', {str(recording)!r}, '-o', {str(image)!r}]))")
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    started = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", program], env=env, cwd=tree, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    if os.waitstatus_to_exitcode(status):
        sys.exit(f"{tree}: plot failed: {child.stderr.read() if child.stderr else ''}")
    image.unlink(missing_ok=True)
    return {"tree": str(tree), "wall_s": round(wall, 1), "peak_mib": round(usage.ru_maxrss / 1024)}  # KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=200_000)
    parser.add_argument("--tree", type=Path, action="append", help="a checkout whose hexactl plots (repeatable)")
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        recording = Path(folder) / "long.csv"
        write_recording(recording, arguments.rows)
        size_mb = recording.stat().st_size / 1e6
        for tree in arguments.tree or [ROOT]:
            print(json.dumps({"rows": arguments.rows, "file_mb": round(size_mb), **plot(tree, recording)}), flush=True)


if __name__ == "__main__":
    main()
