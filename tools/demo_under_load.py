"""``hexactl demo`` beside CPU-bound processes: does it complete, as accurately, and how
many faults of the simulated actuators does it recover from?

    python tools/demo_under_load.py --hogs 4 [--out DIR] [-- DEMO OPTIONS...]

Starts ``--hogs`` processes that spin (``while 1: pass``, normal priority), runs
``hexactl demo --out DIR --force`` beside them, and always kills them afterwards (also on
failure or Ctrl-C). Prints the demo's exit status, duration, the faults it recovered
from, its Table 1 and stroke table, and the load average before and after. ``--hogs 0``
is the unloaded reference.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HOG = "while 1: pass"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hogs", type=int, default=4, help="CPU-bound processes beside the demo (default 4)")
    parser.add_argument("--out", type=Path, help="the demo's directory (default: a new temporary one)")
    parser.add_argument("demo", nargs="*", help="more options for hexactl demo (after --)")
    arguments = parser.parse_args()
    out = arguments.out or Path(tempfile.mkdtemp(prefix="demo-under-load-")) / "out"
    command = [sys.executable, "-m", "hexactl.adapters.cli.main", "demo", "--out", str(out), "--force", *arguments.demo]
    print(f"euid {os.geteuid()}, {os.cpu_count()} CPUs, load average before {os.getloadavg()}, {arguments.hogs} hogs")
    print("$ " + " ".join(command), flush=True)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the hogs are killed on SIGTERM too
    hogs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(arguments.hogs)]
    try:
        started = time.monotonic()
        demo = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        seconds = time.monotonic() - started
    finally:
        for hog in hogs:
            hog.kill()
        for hog in hogs:
            hog.wait()
    print(f"exit status {demo.returncode} after {seconds:.0f} s; load average after {os.getloadavg()}")
    lines = demo.stdout.splitlines()
    shown = [line for line in lines if "fault" in line or line.startswith(("Table 1", "instruction", "before", "after",
                                                                           "x_sweep", "y_rotation", "compound",
                                                                           "X sweep", "the paper", "largest error",
                                                                           "finished"))]
    print("\n".join(shown))
    if demo.returncode != 0:
        print(demo.stdout[-3000:], demo.stderr[-3000:], sep="\n")
    return demo.returncode


if __name__ == "__main__":
    sys.exit(main())
