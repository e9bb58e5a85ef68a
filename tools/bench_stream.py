#!/usr/bin/env python3
"""Benchmark the pose stream: sample-to-set-point latency at 100, 500 and 1000 Hz input,
the transport's share apart from the loop's, and the loop's missed cycles while
streaming, in one run beside cyclictest.

    python3 tools/bench_stream.py                      # 20 s per rate
    python3 tools/bench_stream.py --seconds 10 --json out.json

One ``hexactl serve`` (500 Hz, the built-in simulator, real-time as the process may);
for each input rate a stream of a 1 Hz sine (5 mm in x, 0.3° in roll) sent with
:class:`~hexactl.adapters.api.stream_client.PoseStream` over ZeroMQ from this process,
each sample stamped with this host's monotonic clock, while ``cyclictest`` (one thread
at the loop's period and priority) runs. The service's receiver measures, per target:

- **transport** (``age_ms``): from the sender's stamp to its arrival in the API's process
  (PUSH/PULL over loopback TCP and the receiver's wake-up);
- **loop** (``loop_latency_ms``): from that arrival to the loop cycle that took it, whose
  set-points carry it (the receiver's coalescing to one target a cycle, the workspace
  check, the pipe to the loop's process, the wait for the next cycle).

Sample-to-set-point is their sum (percentiles of the sum are not the sum of
percentiles: both are given). Missed cycles are counted over each phase.

Then how closely the loop follows the stream, apart from any host's timing: the
controller on ideal actuators in simulated time, a 1 Hz, 10 mm sine streamed at 100, 250
and 500 Hz into the 500 Hz loop (:func:`tracking`).
"""

from __future__ import annotations

import argparse
import json
import math
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

from hexactl.adapters.api.client import HexactlClient  # noqa: E402
from hexactl.adapters.api.stream_client import PoseStream  # noqa: E402
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY  # noqa: E402
from tools.serving import serve, wait_for_tool as wait_for  # noqa: E402

RATE_HZ = 500
INPUT_RATES_HZ = (100, 500, 1000)
WAIT_S = 60.0


def status(client: HexactlClient) -> dict[str, Any]:
    return client.call("status")["status"]



def phase(client: HexactlClient, rate_hz: int, seconds: float, workdir: Path, cyclictest_path: str) -> dict[str, Any]:
    cyclictest = Cyclictest(cyclictest_path, round(1e6 / RATE_HZ), int(seconds), DEFAULT_FIFO_PRIORITY,
                            workdir / f"cyclictest-{rate_hz}.json")
    before = status(client)["loop"]
    load_start = load_average()
    cyclictest.start()
    with PoseStream(client, f"bench {rate_hz} Hz", timeout_ms=200) as stream:
        start = time.monotonic()
        n = 0
        while (now := time.monotonic()) - start < seconds:
            t = now - start
            stream.send((5.0 * math.sin(2 * math.pi * t), 0.0, 0.0, 0.3 * math.sin(2 * math.pi * t), 0.0, 0.0), now)
            n += 1
            time.sleep(max(0.0, start + n / rate_hz - time.monotonic()))
        record = status(client)
    wait_for(lambda: status(client)["stream"] is None, "the stream's end")
    reference = cyclictest.result(WAIT_S)
    received, loop = record["stream_input"], record["loop"]
    return {"input_hz": rate_hz, "sent": n, "dropped_by_sender": stream.dropped, "received": received["received"],
            "forwarded": received["forwarded"], "coalesced": received["coalesced"],
            "out_of_order": received["out_of_order"], "clamped": received["clamped"],
            "transport_ms": received["age_ms"], "loop_ms": received["loop_latency_ms"],
            "cycles": loop["cycles"] - before["cycles"], "missed": loop["missed"] - before["missed"],
            "guard_clamps": loop["guard_clamps"], "lateness_p99_us": loop["lateness_us"]["p99"],
            "compute_p50_us": loop["compute_us"]["p50"], "compute_p99_us": loop["compute_us"]["p99"],
            "cyclictest_p99_us": reference["p99_us"], "state": record["state"],
            "load": (load_start[0], load_average()[0])}


def tracking(input_hz: int, seconds: float = 3.0) -> dict[str, float]:
    """How closely the loop follows a 1 Hz, 10 mm sine in x streamed at ``input_hz``:
    the controller on ideal actuators in simulated time (no host timing in it), the
    commanded x against the sine at the same instant, over the last period."""
    from simulated_stream import SimulatedStream

    stream = SimulatedStream(source="tracking")
    cycles, every = round(seconds * 1e9 / stream.period_ns), round(1e9 / stream.period_ns / input_hz)
    errors = []
    for n in range(cycles):
        t = n * stream.period_ns / 1e9
        target = 10.0 * math.sin(2 * math.pi * t)
        if n % every == 0:
            stream.send((target, 0, 0, 0, 0, 0), n, t)
        stream.step()
        if t >= seconds - 1.0:
            errors.append(stream.pose_command[0] - target)
    errors_mm = [abs(e) for e in errors]
    return {"input_hz": input_hz, "max_mm": max(errors_mm), "rms_mm": math.sqrt(sum(e * e for e in errors) / len(errors)),
            "guard_clamps": stream.guard_clamps}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="each rate's length (default 20)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    cyclictest_path = ensure_executables({"cyclictest": "rt-tests"}, lambda line: print(line, file=sys.stderr))["cyclictest"]
    results = []
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-stream-") as directory:
        workdir = Path(directory)
        with serve(workdir, "--rate", str(RATE_HZ)) as served, HexactlClient(served.api, timeout_s=30.0) as client:
            client.call("enable")
            wait_for(lambda: status(client)["state"] == "enabled", "enabled")
            for rate_hz in INPUT_RATES_HZ:
                results.append(phase(client, rate_hz, args.seconds, workdir, cyclictest_path))
    cell = lambda p: f"{p['p50']:.2f} / {p['p99']:.2f}" if p else "–"  # noqa: E731
    print("| input rate | samples sent / forwarded to the loop (coalesced) | transport p50 / p99 ms | loop p50 / p99 ms "
          "| missed cycles / cycles | guard clamps | loop lateness p99 µs / cyclictest p99 µs | compute p50 / p99 µs "
          "| load average |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in results:
        print(f"| {r['input_hz']} Hz | {r['sent']} / {r['forwarded']} ({r['coalesced']}) | {cell(r['transport_ms'])} "
              f"| {cell(r['loop_ms'])} | {r['missed']} / {r['cycles']} | {r['guard_clamps']} "
              f"| {r['lateness_p99_us']:.0f} / {r['cyclictest_p99_us']:.0f} | {r['compute_p50_us']:.0f} / "
              f"{r['compute_p99_us']:.0f} | {r['load'][0]:.2f} → {r['load'][1]:.2f} |")
    followed = [tracking(rate_hz) for rate_hz in (100, 250, 500)]
    print("\n| input rate | |commanded − sine| max mm | RMS mm | guard clamps |")
    print("| --- | --- | --- | --- |")
    for f in followed:
        print(f"| {f['input_hz']} Hz | {f['max_mm']:.3f} | {f['rms_mm']:.3f} | {f['guard_clamps']} |")
    if args.json:
        args.json.write_text(json.dumps({"service": results, "tracking": followed}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
