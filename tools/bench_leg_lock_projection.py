#!/usr/bin/env python3
"""What one leg-lock projection costs (kinematics/leg_lock.py), as the loop makes it each
cycle in leg-lock mode (from the last cycle's answer) and from a pose 30 mm off the
surface; least of 5 runs. Give a checkout's root to measure that revision's code:

    python3 tools/bench_leg_lock_projection.py [CHECKOUT]      # default: this one
"""

from __future__ import annotations

import sys
import timeit
from pathlib import Path

ROOT = Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else Path(__file__).resolve().parents[1]
if not (ROOT / "hexactl" / "__init__.py").is_file():  # else an installed hexactl would be measured instead
    print(f"{sys.argv[1]}: no hexactl package there: give the root of a checkout (e.g. made by git worktree add)\n"
          "usage: python3 tools/bench_leg_lock_projection.py [CHECKOUT]", file=sys.stderr)
    sys.exit(2)
sys.path.insert(0, str(ROOT))

from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.kinematics.inverse import leg_lengths  # noqa: E402
from hexactl.kinematics.leg_lock import LockedLeg  # noqa: E402
from hexactl.kinematics.pose import absolute_from_relative  # noqa: E402

RUNS, CALLS = 5, 20000


def main() -> int:
    geometry = load_geometry(default_config_path())
    at = lambda relative: absolute_from_relative(geometry.home, relative)  # noqa: E731
    constraint = LockedLeg(geometry.legs, 1, leg_lengths(geometry.legs, at([0] * 6))[0],
                           geometry.characteristic_length_mm)
    last = constraint.project(at([10, 5, 20, 1, 2, 3])).pose
    cases = {"from the last cycle's answer": lambda: constraint.project(at([10.2, 5.1, 20.1, 1.001, 2, 3]), start=last),
             "30 mm off the surface": lambda: constraint.project(at([40, 5, 20, 1, 2, 3]))}
    for name, call in cases.items():
        seconds = min(timeit.repeat(call, number=CALLS, repeat=RUNS)) / CALLS
        print(f"{name}: {seconds * 1e6:.2f} µs, {call().iterations} iterations")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
