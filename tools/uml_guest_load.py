"""Where the CPU of the vcan tests' user-mode Linux guest goes: the service and the simulated
actuators on vcan0, set up as tests/vcan/test_service_over_vcan.py sets them up, for
``HEXACTL_GUEST_LOAD_SECONDS`` (default 10) disabled and as long enabled at rest; prints the guest's idle share, each
process's CPU share and the loop's statistics.

Run inside the guest (it is a pytest module, marked ``vcan``)::

    python3 tools/uml_vcan.py -- -q -s tools/uml_guest_load.py

Why: in the guest every system call costs about 0.1 ms (ptrace), the clock included, and
one CPU carries the loop, the simulator, the API and pytest; this shows what a change to the
cycle's system calls is worth there (BENCHMARKS.md, "The service on SocketCAN inside
user-mode Linux").
"""

from __future__ import annotations

import os
import time

import pytest

from tests.vcan.test_service_over_vcan import (  # noqa: F401 - pytest fixtures
    client,
    data_dir,
    enabled_at_rest,
    nominal,
    service,
    simulator,
    status,
)

pytestmark = pytest.mark.vcan

SECONDS = float(os.environ.get("HEXACTL_GUEST_LOAD_SECONDS", "10"))
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def cpu_seconds() -> dict[str, tuple[str, float]]:
    """Every process's command line and CPU seconds (user + system) so far."""
    seen = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline") as cmdline, open(f"/proc/{pid}/stat") as stat:
                command = cmdline.read().replace("\0", " ").strip()[:80]
                fields = stat.read().rpartition(")")[2].split()
        except OSError:
            continue
        seen[pid] = (command, (int(fields[11]) + int(fields[12])) / TICKS_PER_S)
    return seen


def idle_and_total() -> tuple[int, int]:
    with open("/proc/stat") as stat:
        ticks = [int(value) for value in stat.readline().split()[1:]]
    return ticks[3], sum(ticks)


def test_guest_load(client) -> None:  # noqa: F811 - the fixture
    for phase in ("disabled", "enabled at rest"):
        if phase != "disabled":
            enabled_at_rest(client)
        before, (idle_0, total_0), start = cpu_seconds(), idle_and_total(), time.monotonic()
        time.sleep(SECONDS)
        after, (idle_1, total_1), wall = cpu_seconds(), idle_and_total(), time.monotonic() - start
        print(f"\n{phase}: guest idle {(idle_1 - idle_0) / (total_1 - total_0):.0%} over {wall:.1f} s")
        for pid, (command, used) in after.items():
            if pid in before and (share := (used - before[pid][1]) / wall) >= 0.01:
                print(f"  {share:4.0%}  {command}")
        loop = status(client)["loop"]
        print(f"  loop: compute p50 {loop['compute_us']['p50']:.0f} µs, p99 {loop['compute_us']['p99']:.0f} µs; "
              f"lateness p50 {loop['lateness_us']['p50']:.0f} µs, max {loop['lateness_us']['max']:.0f} µs; "
              f"{loop['missed']} of {loop['cycles']} cycles missed so far")
