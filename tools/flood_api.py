#!/usr/bin/env python3
"""Flood the command API of a real service with many clients at once and see what the
loop, the actuators and an operator get meanwhile.

    python tools/flood_api.py                               # 200 clients x 50 requests, the figures in BENCHMARKS.md
    python tools/flood_api.py --clients 20 --requests 20    # a small run

The target: the service on its simulator at the settings ``hexactl serve`` uses by
default (:class:`soak.MonitoredService`, a bus monitor on its bus), enabled and moving.
``--processes`` processes each open their share of ``--clients`` DEALER sockets and send
every client's ``--requests`` at once (``status``, ``validate_pose`` and ``move`` to
random poses in half the envelope), without waiting for replies, then collect them. An
operator client meanwhile sends ``stop`` every ``--operator-every`` seconds and times
its answer (``stop`` goes ahead of every queued request); ``--operator-command enable``
sends an ``enable`` instead (already enabled: nothing to do), a command that waits its turn
in the queues as the flood's do: the admission control's fairness to a client with nothing
queued.

Prints the answers by command and outcome (``busy`` is the admission control refusing
what it cannot queue), the requests never answered, the operator's latencies,
the loop's missed cycles before and after, the faults that latched, and the monitor's
figures. Exit status 0 if every request was answered, none with ``internal_error``, no
fault latched and the monitor saw no violation; else 1.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import random
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import zmq

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from soak import MonitoredService, Scheduling, loop_difference, print_monitor, random_pose, realtime_line  # noqa: E402

from hexactl.adapters.api.client import HexactlClient  # noqa: E402
from hexactl.adapters.api.protocol import PROTOCOL_VERSION  # noqa: E402
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY  # noqa: E402

COLLECT_TIMEOUT_S = 60.0
"""A request unanswered this long after the last was sent counts as never answered."""


def flood_process(endpoint: str, clients: int, requests: int, seed: int, envelope: tuple[list[float], list[float]],
                  results: multiprocessing.Queue) -> None:
    """One process's share: ``clients`` sockets, each sends ``requests`` at once, then
    every reply is collected; puts the outcome counts and the unanswered count."""
    rng = random.Random(seed)
    low, high = envelope
    context = zmq.Context()
    sockets = []
    outcomes: Counter[str] = Counter()
    try:
        for _ in range(clients):
            socket = context.socket(zmq.DEALER)
            socket.linger = 0
            socket.connect(endpoint)
            sockets.append(socket)
        pending: dict[zmq.Socket, dict[int, str]] = {socket: {} for socket in sockets}
        for number in range(requests):
            for socket in sockets:
                cmd = rng.choice(("status", "validate_pose", "move"))
                fields: dict[str, Any] = {}
                if cmd != "status":
                    fields["pose"] = [round(rng.uniform(0.5 * a, 0.5 * b), 3) for a, b in zip(low, high)]
                socket.send(json.dumps({"v": PROTOCOL_VERSION, "id": number, "cmd": cmd, **fields}).encode())
                pending[socket][number] = cmd
        poller = zmq.Poller()
        for socket in sockets:
            poller.register(socket, zmq.POLLIN)
        deadline = time.monotonic() + COLLECT_TIMEOUT_S
        while any(pending.values()) and time.monotonic() < deadline:
            for socket, _ in poller.poll(100):
                reply = json.loads(socket.recv_multipart()[-1])
                cmd = pending[socket].pop(reply.get("id"), "unexpected")
                outcomes[f"{cmd}:{'ok' if reply.get('ok') else reply['error']['code']}"] += 1
        results.put((dict(outcomes), sum(len(waiting) for waiting in pending.values())))
    finally:
        for socket in sockets:
            socket.close()
        context.term()


class Operator(threading.Thread):
    """Sends ``command`` every ``every_s`` and keeps each answer's round trip (ms)."""

    def __init__(self, endpoint: str, every_s: float, command: str = "stop") -> None:
        super().__init__(name="flood-operator", daemon=True)
        self.endpoint, self.every_s, self.command = endpoint, every_s, command
        self.latencies_ms: list[float] = []
        self.refusals: Counter[str] = Counter()
        self._stopping = threading.Event()

    def run(self) -> None:
        with HexactlClient(self.endpoint, timeout_s=COLLECT_TIMEOUT_S) as client:
            while not self._stopping.wait(self.every_s):
                start = time.perf_counter()
                reply = client.request(self.command)
                self.latencies_ms.append((time.perf_counter() - start) * 1e3)
                if not reply["ok"]:
                    self.refusals[reply["error"]["code"]] += 1

    def stop(self) -> None:
        self._stopping.set()
        self.join()


SERVE_DEFAULT = Scheduling(fifo_priority=DEFAULT_FIFO_PRIORITY, lock_memory=True)
"""What ``hexactl serve`` asks for by default (it falls back, and says so, without the privilege)."""


def flood(clients: int, requests: int, processes: int, operator_every_s: float, seed: int,
          scheduling: Scheduling = SERVE_DEFAULT, operator_command: str = "stop") -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="hexactl-flood-") as directory, \
            MonitoredService(Path(directory), scheduling=scheduling) as harness:
        harness.ensure_enabled()
        rng = random.Random(seed)
        harness.operator.call("move", pose=random_pose(harness.geometry, rng))
        envelope = (list(harness.geometry.limits.pose_min), list(harness.geometry.limits.pose_max))
        before = harness.loop_figures()
        operator = Operator(harness.api_endpoint, operator_every_s, operator_command)
        operator.start()
        context = multiprocessing.get_context("spawn")
        results = context.Queue()
        shares = [clients // processes + (index < clients % processes) for index in range(processes)]
        workers = [context.Process(target=flood_process, args=(harness.api_endpoint, share, requests, seed + index,
                                                               envelope, results))
                   for index, share in enumerate(shares) if share]
        started = time.monotonic()
        for worker in workers:
            worker.start()
        outcomes: Counter[str] = Counter()
        unanswered = 0
        for _ in workers:
            counts, missing = results.get(timeout=COLLECT_TIMEOUT_S * 4)
            outcomes.update(counts)
            unanswered += missing
        for worker in workers:
            worker.join()
        seconds = time.monotonic() - started
        operator.stop()
        after = harness.loop_figures()
        status = harness.status()
        latencies = sorted(operator.latencies_ms)
        return {
            "clients": clients,
            "requests_per_client": requests,
            "seconds": round(seconds, 2),
            "realtime": harness.realtime,
            "outcomes": dict(sorted(outcomes.items())),
            "unanswered": unanswered,
            "internal_errors": sum(n for key, n in outcomes.items() if key.endswith(":internal_error")),
            "operator_ms": {
                "command": operator_command,
                "count": len(latencies),
                "p50": round(latencies[len(latencies) // 2], 2) if latencies else None,
                "p99": round(latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))], 2) if latencies else None,
                "max": round(latencies[-1], 2) if latencies else None,
                "refused": dict(operator.refusals),
            },
            "loop": loop_difference(before, after),
            "state_after": status["state"],
            "faults_latched": [f"{fault['code']}: {fault['message']}" for fault in status["faults"]],
            "monitor": harness.monitor_figures(),
        }


def passed(result: dict[str, Any]) -> bool:
    return (result["unanswered"] == 0 and result["internal_errors"] == 0 and not result["faults_latched"]
            and result["state_after"] == "enabled" and result["monitor"]["violations"] == 0)


def print_report(result: dict[str, Any]) -> None:
    print(f"flood: {result['clients']} clients x {result['requests_per_client']} requests in {result['seconds']} s; "
          f"{realtime_line(result['realtime'])}")
    for key, count in result["outcomes"].items():
        print(f"  {key:40s} {count}")
    print(f"  unanswered: {result['unanswered']}; internal errors: {result['internal_errors']}")
    operator = result["operator_ms"]
    print(f"  operator {operator['command']}: {operator['count']} sent, answered in p50 {operator['p50']} ms, p99 "
          f"{operator['p99']} ms, max {operator['max']} ms; refused {operator['refused'] or 'none'}")
    loop = result["loop"]
    print(f"  loop: {loop['cycles']} cycles in {loop['seconds']} s ({loop['achieved_rate_hz']} Hz), missed {loop['missed']}, "
          f"guard clamps {loop['guard_clamps']}")
    print(f"  state after: {result['state_after']}; faults latched: {result['faults_latched'] or 'none'}")
    print_monitor(result["monitor"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clients", type=int, default=200)
    parser.add_argument("--requests", type=int, default=50, help="requests per client, all sent at once")
    parser.add_argument("--processes", type=int, default=4, help="processes the clients are spread over")
    parser.add_argument("--operator-every", type=float, default=1.0, help="seconds between the operator's commands")
    parser.add_argument("--operator-command", choices=("stop", "enable"), default="stop",
                        help="what the operator sends: stop (ahead of every queued request) or enable (queued)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-realtime", action="store_true", help="normal scheduling, as 'hexactl serve --no-realtime'")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    arguments = parser.parse_args(argv)
    result = flood(arguments.clients, arguments.requests, arguments.processes, arguments.operator_every,
                   arguments.seed, Scheduling() if arguments.no_realtime else SERVE_DEFAULT, arguments.operator_command)
    print_report(result)
    if arguments.json:
        arguments.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0 if passed(result) else 1


if __name__ == "__main__":
    sys.exit(main())
