#!/usr/bin/env python3
"""Benchmark the dashboard: the end-to-end latency from a telemetry record to its drawing
in a real browser, and the control loop with and without a dashboard attached, in one run
beside cyclictest.

    python3 tools/bench_dashboard.py                 # 30 s per phase
    python3 tools/bench_dashboard.py --seconds 10 --json out.json

One ``hexactl serve`` (the built-in simulator; real-time as the process may) plays the
built-in X sweep over and over, so that every record changes what is drawn. Two phases of
``--seconds`` each:

1. **without** a dashboard;
2. ``hexactl dashboard`` **served**, subscribed to the telemetry, no page open;
3. **with** a headless Chromium (Debian's, software WebGL) on its page, drawing the 3D
   view and the plots, on this same machine.

In each phase ``cyclictest`` (one thread at the loop's period, SCHED_FIFO at the loop's
priority) measures what this machine's scheduler gives at the same time, and the loop's
own statistics give its missed cycles (counted over the phase) and its lateness and
compute percentiles (the service's stats window, which the phase fits in).

The latency is the page's own measure of each record it draws: the record's age when the
dashboard forwarded it (the service's monotonic clock is this host's) plus the time from
then to the end of the animation frame that drew it. It includes the PUB/SUB hop, the
dashboard's WebSocket, the page's parsing and the three.js and uPlot drawing.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from _debian import ensure_executables  # noqa: E402
from bench_service import Cyclictest, load_average  # noqa: E402

from hexactl.adapters.api.client import CommandError, HexactlClient  # noqa: E402
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY  # noqa: E402
from tools.browser import dashboard, headless_chromium  # noqa: E402
from tools.serving import serve, wait_for_tool as wait_for  # noqa: E402

RATE_HZ = 500
WAIT_S = 60.0



def keep_moving(client: HexactlClient) -> int:
    """Play the X sweep again if it ended; a fault latched meanwhile (a loaded host stalls
    the simulated actuators past their watchdog) is reset and counted: returns 1 then."""
    record = client.call("status")["status"]
    if record["state"] == "estop":
        raise SystemExit(f"the controller is in estop: {record['faults']}")
    if record["state"] == "fault":
        print(f"fault latched, reset: {record['faults']}", file=sys.stderr)
        client.call("reset")
        wait_for(lambda: client.call("status")["status"]["state"] == "disabled", "reset")
        client.call("enable")
        wait_for(lambda: client.call("status")["status"]["state"] == "enabled", "enabled")
        return 1
    if record["sequence"] is None:
        try:
            client.call("play", sequence="x_sweep")
        except CommandError as error:
            if error.code not in ("busy", "latched"):  # latched between status and play: reset next time
                raise
    return 0


def phase(client: HexactlClient, seconds: float, workdir: Path, name: str, cyclictest_path: str) -> dict[str, Any]:
    """The loop's figures over ``seconds`` of motion, cyclictest beside it."""
    cyclictest = Cyclictest(cyclictest_path, round(1e6 / RATE_HZ), int(seconds), DEFAULT_FIFO_PRIORITY,
                            workdir / f"cyclictest-{name}.json")
    start = client.call("status")["status"]["loop"]
    load_start = load_average()
    cyclictest.start()
    end_at = time.monotonic() + seconds
    faults = 0
    while time.monotonic() < end_at:
        faults += keep_moving(client)
        time.sleep(0.5)
    loop = client.call("status")["status"]["loop"]
    reference = cyclictest.result(WAIT_S)
    return {"phase": name, "cycles": loop["cycles"] - start["cycles"], "missed": loop["missed"] - start["missed"],
            "lateness_p50_us": loop["lateness_us"]["p50"], "lateness_p99_us": loop["lateness_us"]["p99"],
            "compute_p50_us": loop["compute_us"]["p50"], "compute_p99_us": loop["compute_us"]["p99"],
            "cyclictest_p50_us": reference["p50_us"], "cyclictest_p99_us": reference["p99_us"],
            "faults": faults, "load_start": load_start, "load_end": load_average()}


def _figure(value: float | int | None) -> str:
    """A table cell: counts as they are, µs to 0.1 below 10 and whole above."""
    if value is None or isinstance(value, int):
        return str(value)
    return f"{value:.1f}" if abs(value) < 10 else f"{value:.0f}"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q / 100.0 * len(ordered)))]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="each phase's length (default 30; at most the "
                        "loop's stats window, 32.8 s at 500 Hz)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    cyclictest_path = ensure_executables({"cyclictest": "rt-tests"}, lambda line: print(line, file=sys.stderr))["cyclictest"]
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        workdir = Path(directory)
        with serve(workdir, "--rate", str(RATE_HZ)) as served, HexactlClient(served.api, timeout_s=30.0) as client:
            client.call("enable")
            wait_for(lambda: client.call("status")["status"]["state"] == "enabled", "enabled")
            keep_moving(client)
            without = phase(client, args.seconds, workdir, "without", cyclictest_path)
            with dashboard(served.api, served.telemetry) as board:
                served_only = phase(client, args.seconds, workdir, "served", cyclictest_path)
                driver = headless_chromium()
                try:
                    driver.get(board.url)
                    wait_for(lambda: driver.execute_script("return document.body.dataset.connected") == "true",
                             "the page connected")
                    before = len(driver.execute_script("return window.hexactlDashboard.latencies()"))
                    attached = phase(client, args.seconds, workdir, "with", cyclictest_path)
                    # The page keeps the last 2000: a phase of ≤ 38 s at 50 records/s fits.
                    latencies = driver.execute_script("return window.hexactlDashboard.latencies()")[before:]
                finally:
                    driver.quit()
    if not latencies:
        raise SystemExit("the page drew no record")
    drawn = {"records_drawn": len(latencies), "latency_p50_ms": statistics.median(latencies),
             "latency_p99_ms": percentile(latencies, 99.0), "latency_max_ms": max(latencies)}
    phases = (without, served_only, attached)
    print("| | without a dashboard | the dashboard, no page open | the dashboard and Chromium on its page |")
    print("| --- | --- | --- | --- |")
    for key, label in (("cycles", "loop cycles"), ("missed", "missed (> T/2 late)"),
                       ("lateness_p50_us", "lateness p50 µs, loop"), ("lateness_p99_us", "lateness p99 µs, loop"),
                       ("cyclictest_p50_us", "cyclictest p50 µs"), ("cyclictest_p99_us", "cyclictest p99 µs"),
                       ("compute_p50_us", "compute p50 µs"), ("compute_p99_us", "compute p99 µs"),
                       ("faults", "faults latched (reset)")):
        print(f"| {label} | " + " | ".join(_figure(figures[key]) for figures in phases) + " |")
    print("| load average (1 min) start → end | " + " | ".join(
        f"{figures['load_start'][0]:.2f} → {figures['load_end'][0]:.2f}" for figures in phases) + " |")
    print(f"\nrecord → drawing: p50 {drawn['latency_p50_ms']:.1f} ms, p99 {drawn['latency_p99_ms']:.1f} ms, "
          f"max {drawn['latency_max_ms']:.1f} ms over {drawn['records_drawn']} records drawn")
    if args.json:
        args.json.write_text(json.dumps({"without": without, "served": served_only, "with": attached, "drawing": drawn},
                                        indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
