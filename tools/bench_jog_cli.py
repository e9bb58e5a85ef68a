#!/usr/bin/env python3
"""How far ``hexactl jog z=10 --for 1`` takes the platform on the real service: 10 mm at
10 mm/s for 1 s, plus what the release's latency (the CLI's last renewal, its release
request, the loop's braking) adds. The service with its built-in simulator runs in a
process of its own (as ``hexactl serve`` does), the command line in this one, as an
operator runs it; back at the zero posture before each run.

    python3 tools/bench_jog_cli.py --runs 5
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.api.client import HexactlClient  # noqa: E402
from hexactl.adapters.cli.main import main as hexactl  # noqa: E402
from hexactl.application.service import ServiceConfig, ServiceProcess  # noqa: E402
from tools.serving import wait_until  # noqa: E402

ASKED_MM = 10.0  # z=10 mm/s for 1 s
WAIT_S = 60.0


def at_rest(client: HexactlClient) -> dict:
    """The status record once the platform is at rest with no jog (SystemExit after WAIT_S)."""
    status = lambda: client.call("status")["status"]  # noqa: E731
    return wait_until(lambda: (record := status())["motion"] == "holding" and record["jog"] is None and record,
                      "the platform at rest", WAIT_S, seen=lambda: status()["faults"], failure=SystemExit)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="jogs (default 5)")
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        service = ServiceProcess(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                               data_dirs=(Path(directory),), log_level="WARNING",
                                               kept_calibration_path=Path(directory) / "kept.toml"))
        try:
            with HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
                client.call("enable")
                travelled, took = [], []
                for _ in range(arguments.runs):
                    client.call("move", pose=[0.0] * 6, duration=1.0)
                    at_rest(client)
                    started = time.monotonic()
                    with contextlib.redirect_stdout(io.StringIO()):
                        status = hexactl(["jog", "z=10", "--for", "1", "--api", service.api_endpoint])
                    took.append(time.monotonic() - started)
                    if status != 0:
                        raise SystemExit(f"hexactl jog exited {status}")
                    travelled.append(at_rest(client)["pose_command"][2])
        finally:
            service.close()
    over = [z - ASKED_MM for z in travelled]
    print(f"travelled: median {statistics.median(travelled):.2f} mm, max {max(travelled):.2f} mm "
          f"(asked {ASKED_MM:g} mm); past it: median {statistics.median(over):.2f} mm, max {max(over):.2f} mm; "
          f"command line to rest: median {statistics.median(took):.2f} s, max {max(took):.2f} s ({arguments.runs} runs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
