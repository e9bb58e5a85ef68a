"""How the API answers while the control loop's process is stopped (SIGSTOP; a hung loop
alike): ``hexactl serve --no-realtime`` (the built-in simulator), enabled, its loop's
process stopped; once ``status`` shows the loop silent for over a second, ``--moves``
moves are sent one after another, then a ``status`` and an ``estop``. Per request: the
reply's time and code, or none within ``--timeout`` (after which the tool sends nothing
more: the API is held up). Then the loop is continued and the tool reports whether the
E-stop was carried out.

    python3 tools/bench_stopped_loop.py --moves 300
"""

from __future__ import annotations

import argparse
import signal
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # noqa: E402
from tools.serving import serve, wait_for_tool as wait_for  # noqa: E402


def timed(client: HexactlClient, command: str, **fields: Any) -> tuple[float, str]:
    """The reply's wall time (s) and code (``ok``, the error's, or ``no reply``)."""
    started = time.monotonic()
    try:
        reply = client.request(command, **fields)
    except ServiceUnavailable:
        return time.monotonic() - started, "no reply"
    return time.monotonic() - started, "ok" if reply["ok"] else reply["error"]["code"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--moves", type=int, default=300)
    parser.add_argument("--timeout", type=float, default=5.0, help="a reply's wait, s (default 5)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hexactl-stopped-loop-") as directory, \
            serve(Path(directory), "--no-realtime") as served, \
            HexactlClient(served.api, timeout_s=args.timeout) as client:
        wait_for(lambda: client.request("enable")["ok"] or None, "the actuators to enable")
        served.process.send_signal(signal.SIGSTOP)  # the loop's process; the API's is its child
        try:
            wait_for(lambda: client.call("status")["status"]["loop"].get("report_age_s", 2.0) > 1.0,
                     "the loop's silence seen")
            moves: list[tuple[float, str]] = []
            for index in range(args.moves):
                moves.append(timed(client, "move", pose=[0, 0, 1 + index / args.moves, 0, 0, 0], duration=1.0))
                if moves[-1][1] == "no reply":
                    break
            status, estop = timed(client, "status"), timed(client, "estop")
        finally:
            served.process.send_signal(signal.SIGCONT)
        try:
            carried_out = wait_for(lambda: client.call("status")["status"]["state"] == "estop", "the E-stop")
        except (SystemExit, ServiceUnavailable):
            carried_out = False
    seconds = [s for s, _ in moves]
    print(f"moves sent: {len(moves)} of {args.moves}; replies: {dict(Counter(code for _, code in moves))}")
    print(f"move reply: median {statistics.median(seconds) * 1e3:.0f} ms, max {max(seconds) * 1e3:.0f} ms")
    print(f"then status: {status[1]} after {status[0] * 1e3:.0f} ms; estop: {estop[1]} after {estop[0] * 1e3:.0f} ms")
    print(f"the E-stop carried out once the loop ran again: {'yes' if carried_out else 'no'}")


if __name__ == "__main__":
    main()
