"""What the loop's supervision costs per cycle: ``Supervisor.faults`` on six healthy
enabled legs, as the loop calls it every cycle, least of ``--repeats`` timings of
``--calls`` calls, in µs per call. ``--tree`` measures another checkout's hexactl (e.g. a
``git worktree`` of the revision before a change), in a fresh process each:

    python3 tools/bench_supervisor.py
    python3 tools/bench_supervisor.py --tree /tmp/base --tree .
"""

from __future__ import annotations

import argparse
import inspect
import subprocess
import sys
import timeit
from pathlib import Path


def measure(calls: int, repeats: int) -> float:
    """µs per ``faults()`` call of the hexactl on the path."""
    from hexactl.control.config import SupervisionConfig
    from hexactl.control.hardware import ActuatorFeedback, ActuatorState, BusState, FeedbackSnapshot, LinkHealth
    from hexactl.control.supervisor import Supervisor

    if len(inspect.signature(Supervisor).parameters) == 3:  # since the locked leg's supervision: a leg's step a cycle
        supervisor = Supervisor(SupervisionConfig(), 0.002, 0.8)  # 400 mm/s × 2 ms
    else:
        supervisor = Supervisor(SupervisionConfig(), 0.002)
    supervisor.enabled(0)
    # Since the fault bits are named; a tree from before has no such field.
    named = {"fault_names": ()} if "fault_names" in inspect.signature(ActuatorFeedback).parameters else {}
    healthy = ActuatorFeedback(position_mm=100.0, velocity_mm_s=0.0, state=ActuatorState.ENABLED, fault_bits=0, **named,
                               heartbeat_age_s=0.001, setpoint_counter=100)
    feedback, link = FeedbackSnapshot((healthy,) * 6, 0), LinkHealth(BusState.ACTIVE, 0)
    if len(inspect.signature(supervisor.sent).parameters) == 3:  # since the following error: the set-points too
        supervisor.sent(100, (100.0,) * 6, True)
    else:
        supervisor.sent(True)
    supervisor.faults(feedback, link, 100, 1)  # the legs arrived in ENABLED
    return min(timeit.repeat(lambda: supervisor.faults(feedback, link, 100, 2), number=calls, repeat=repeats)) / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--tree", type=Path, action="append", help="a checkout to measure (default: this one)")
    arguments = parser.parse_args()
    if not arguments.tree:
        print(f"{measure(arguments.calls, arguments.repeats):.2f} µs per faults()")
        return
    for tree in arguments.tree:
        if not (tree / "hexactl" / "__init__.py").is_file():  # else an installed hexactl would be measured instead
            parser.error(f"{tree}: no hexactl package there: give the root of a checkout (e.g. made by git worktree add)")
    for tree in arguments.tree:
        code = (f"import sys; sys.path.insert(0, {str(tree.resolve())!r}); sys.path.insert(1, {str(Path(__file__).parent)!r}); "
                f"import bench_supervisor; print(f'{{bench_supervisor.measure({arguments.calls}, {arguments.repeats}):.2f}}')")
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        print(f"{tree}: {result.stdout.strip()} µs per faults()")


if __name__ == "__main__":
    main()
