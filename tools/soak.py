#!/usr/bin/env python3
"""Soak the whole service: sequences played back to back with API traffic beside them,
for ``--minutes`` at ``--rate`` Hz, every set-point checked by an independent bus monitor.

    python tools/soak.py --minutes 10                  # the figures in BENCHMARKS.md
    python tools/soak.py --seconds 20 --json soak.json

What runs, in a child process: ``Service.start`` on its simulator (six simulated actuator
firmwares on a private ``virtual:`` bus) and a
:class:`~hexactl.adapters.can.bus_monitor.BusMonitor` on that bus. The operator (this
process's main thread) keeps the platform enabled and playing: the built-in sequences and a seeded
inline one in turn, each saved with ``save_recording`` when it ends; every
``--swap-every`` seconds it loads a calibration variant (zero lengths off by up to 1 mm)
or rolls it back, while the sequence plays. A second client, in its own thread, asks
``status`` and ``validate_pose`` (a random pose in the envelope) at ``--traffic-hz``, and
a telemetry subscriber reads every record.

It reports the loop's figures (cycles, achieved rate, missed and skipped cycles, lateness
and compute percentiles over the loop's recent window and the maxima over the run, GC,
guard clamps), the requests by command and outcome, the faults the controller latched
(each recovered with ``reset`` and ``enable``, and counted), and the monitor's counts.

Exit status 0 when the monitor saw no violation, every request was answered and none
failed with ``internal_error``; 1 otherwise. Missed cycles and faults are reported, not
judged: they depend on the machine.

:class:`MonitoredService` (service + monitor + operator client) is also what
``tools/fuzz_api.py`` runs against.
"""

from __future__ import annotations

import argparse
import json
import random
import re
import signal
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from types import TracebackType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber  # noqa: E402
from hexactl.adapters.can.bus_monitor import BusMonitor  # noqa: E402
from hexactl.adapters.files.geometry_file import default_config_path, geometry_to_toml, load_geometry  # noqa: E402
from hexactl.adapters.service import Service, ServiceConfig, ServiceError  # noqa: E402
from hexactl.adapters.spawned import STOP, Spawned, SpawnError  # noqa: E402
from hexactl.control.sequences import BUILTIN_SEQUENCES  # noqa: E402
from hexactl.kinematics.geometry import Geometry  # noqa: E402

LOCAL = "tcp://127.0.0.1:*"
REQUEST_TIMEOUT_S = 30.0  # generous: a loaded machine; a request unanswered this long counts as missing
ENABLE_TIMEOUT_S = 30.0
RESET_RETRY_S = 0.1  # a reset's CLEAR_FAULT may wait for the actuators' E-stop hold-off (0.3 s)
ENVELOPE_FRACTION = 0.5  # random poses stay within this share of the pose envelope
START_TIMEOUT_S = 60.0
MONITOR = "monitor"  # the request for the monitor's figures


class MonitoredService:
    """The service on its simulator with a bus monitor on its bus from before the first
    enable, both in a child process of their own (as ``hexactl serve`` would run, so
    that this process's work, e.g. hypothesis generating requests, never holds the loop's
    GIL), and an operator client here; a context manager.

    ``data_dir``: the service's only data directory.
    """

    def __init__(self, data_dir: Path, rate_hz: int = 500, config_path: Path | None = None) -> None:
        self.data_dir = data_dir
        self.rate_hz = rate_hz
        self.geometry = load_geometry(config_path or default_config_path())
        config = ServiceConfig(config_path=config_path, api_endpoint=LOCAL, telemetry_endpoint=LOCAL,
                               data_dirs=(data_dir,), rate_hz=rate_hz, log_level="WARNING")
        try:
            self._child = Spawned(_serve_monitored, (config, self.geometry), name="monitored service", daemon=False,
                                  start_timeout_s=START_TIMEOUT_S)  # fmt: skip
        except SpawnError as error:
            raise SystemExit(f"the service did not start: {error}") from None
        self.api_endpoint, self.telemetry_endpoint = self._child.served
        self.operator = HexactlClient(self.api_endpoint, timeout_s=REQUEST_TIMEOUT_S)
        self.recoveries: Counter[str] = Counter()
        """Why the platform had to be enabled again: ``estop``, ``disabled`` or the first latched
        fault's code; :attr:`recovery_reasons` has its messages."""
        self.recovery_reasons: Counter[str] = Counter()

    def __enter__(self) -> MonitoredService:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        self.operator.close()
        self._child.close(START_TIMEOUT_S)

    def status(self) -> dict[str, Any]:
        """The current telemetry record."""
        return self.operator.call("status")["status"]

    def ensure_enabled(self) -> str | None:
        """Enabled again if it was not: ``reset`` when latched, then ``enable``. Returns
        why it was not (``estop``, ``disabled`` or the first latched fault's code), counted
        in :attr:`recoveries`, or None when it was enabled.

        :raises TimeoutError: if it cannot be enabled within ENABLE_TIMEOUT_S
        """
        record = self.status()
        if record["state"] == "enabled":
            return None
        first = record["faults"][0] if record["state"] == "fault" and record["faults"] else None
        cause = first["code"] if first else record["state"]
        self.recoveries[cause] += 1
        if first:
            self.recovery_reasons[re.sub(r"^leg \d ", "", first["message"])] += 1
        if record["state"] in ("fault", "estop"):
            self.operator.call("reset")
        deadline = time.monotonic() + ENABLE_TIMEOUT_S
        while time.monotonic() < deadline:
            reply = self.operator.request("enable")
            if reply["ok"] or reply["error"]["code"] == "already_enabled":
                return cause
            if reply["error"]["code"] == "actuator_fault":  # CLEAR_FAULT still pending or refused: again
                self.operator.call("reset")
            time.sleep(RESET_RETRY_S)
        raise TimeoutError(f"the service could not be enabled again after {cause} (last: {reply['error']})")

    def loop_figures(self) -> dict[str, Any]:
        """The loop's counters and timing from a fresh ``status``, with its time ``t`` (s)."""
        record = self.status()
        return {"t": record["t"], **record["loop"]}

    def monitor_figures(self) -> dict[str, Any]:
        """The monitor's report (after catching up with the bus) and its first violations.

        :raises SystemExit: if the service's process does not answer
        """
        figures = self._child.request(MONITOR, REQUEST_TIMEOUT_S)
        if not isinstance(figures, dict):
            raise SystemExit("the monitored service's process did not answer")
        return figures


def _serve_monitored(config: ServiceConfig, geometry: Geometry, control: Connection) -> None:
    """The monitored service's process (:class:`MonitoredService`): serve, and answer
    :data:`MONITOR` with the monitor's figures, until told to stop. The monitor stops
    after the service, so that its shutdown (brake, disable) is watched too."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        service = Service.start(config)
    except ServiceError as error:
        control.send(str(error))
        return
    monitor = BusMonitor(service.simulator.bus_spec, geometry, config.rate_hz).start()
    try:
        control.send((service.api_endpoint, service.telemetry_endpoint))
        while (word := control.recv()) != STOP:
            control.send(_monitor_figures(monitor) if word == MONITOR else word)
    except EOFError:
        pass  # the parent is gone: stop too
    finally:
        service.close()
        monitor.stop()


def _monitor_figures(monitor: BusMonitor) -> dict[str, Any]:
    monitor.catch_up()
    report = monitor.report()
    return {
        "counts": report.counts,
        "violations": report.violations,
        "first_violations": [f"{v.what}: {v.message}" for v in monitor.violations[:5]],
        "max_step_fraction": round(report.max_step_fraction, 4),
        "min_stroke_margin_mm": None if report.min_stroke_margin_mm == float("inf") else report.min_stroke_margin_mm,
        "max_cycle_gap_ms": round(report.max_cycle_gap_s * 1e3, 3),
    }


def loop_difference(before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    """What the loop did between two :meth:`MonitoredService.loop_figures`."""
    elapsed = after["t"] - before["t"]
    cycles = after["cycles"] - before["cycles"]
    return {
        "seconds": round(elapsed, 3),
        "cycles": cycles,
        "achieved_rate_hz": round(cycles / elapsed, 2) if elapsed > 0 else None,
        "missed": after["missed"] - before["missed"],
        "skipped": after["skipped"] - before["skipped"],
        "missed_before": before["missed"],
        "missed_after": after["missed"],
        "lateness_us": after["lateness_us"],
        "compute_us": after["compute_us"],
        "gc_runs": after["gc_runs"] - before["gc_runs"],
        "gc_max_us": after["gc_max_us"],
        "guard_clamps": after["guard_clamps"],
    }


def calibration_variants(geometry: Geometry, seed: int, count: int) -> list[str]:
    """``count`` calibration texts: ``geometry`` with each zero length off by up to 1 mm."""
    rng = random.Random(seed)
    variants = []
    for index in range(count):
        zero = tuple(length + rng.uniform(-1.0, 1.0) for length in geometry.zero_lengths)
        variants.append(geometry_to_toml(geometry.model_copy(update={"name": f"soak variant {index}", "zero_lengths": zero})))
    return variants


def random_pose(geometry: Geometry, rng: random.Random, fraction: float = ENVELOPE_FRACTION) -> list[float]:
    """A pose within ``fraction`` of the pose envelope (relative mm and deg)."""
    low, high = geometry.limits.pose_min, geometry.limits.pose_max
    return [round(rng.uniform(fraction * a, fraction * b), 3) for a, b in zip(low, high)]


def inline_sequence(geometry: Geometry, rng: random.Random, name: str) -> dict[str, Any]:
    """Five random waypoints and home, short dwells."""
    waypoints = [{"pose": random_pose(geometry, rng), "dwell": 0.2} for _ in range(5)]
    return {"name": name, "waypoints": [*waypoints, {"pose": [0.0] * 6, "dwell": 0.2}]}


class Traffic(threading.Thread):
    """A second client asking ``status`` and ``validate_pose`` at ``rate_hz``, and a
    telemetry subscriber reading every record, until :meth:`stop`."""

    def __init__(self, harness: MonitoredService, rate_hz: float, seed: int) -> None:
        super().__init__(name="soak-traffic", daemon=True)
        self.harness = harness
        self.period_s = 1.0 / rate_hz
        self.rng = random.Random(seed)
        self.outcomes: Counter[str] = Counter()
        self.telemetry_records = 0
        self._stopping = threading.Event()

    def run(self) -> None:
        harness = self.harness
        with HexactlClient(harness.api_endpoint, timeout_s=REQUEST_TIMEOUT_S) as client, \
                TelemetrySubscriber(harness.telemetry_endpoint, conflate=False) as telemetry:
            while not self._stopping.is_set():
                record(self.outcomes, client, "status")
                record(self.outcomes, client, "validate_pose", pose=random_pose(self.harness.geometry, self.rng))
                while telemetry.socket.poll(0):
                    telemetry.socket.recv()
                    self.telemetry_records += 1
                self._stopping.wait(self.period_s)

    def stop(self) -> None:
        self._stopping.set()
        self.join()


def record(outcomes: Counter[str], client: HexactlClient, cmd: str, **fields: Any) -> dict[str, Any] | None:
    """Send a request, count its outcome as ``cmd:ok``, ``cmd:<code>`` or ``cmd:missing``."""
    try:
        reply = client.request(cmd, **fields)
    except ServiceUnavailable:
        outcomes[f"{cmd}:missing"] += 1
        return None
    outcomes[f"{cmd}:{'ok' if reply['ok'] else reply['error']['code']}"] += 1
    return reply


def soak(duration_s: float, rate_hz: int, swap_every_s: float, traffic_hz: float, seed: int,
         progress: Callable[[str], None] = lambda line: None) -> dict[str, Any]:
    """Run the soak; the figures (see the module docstring)."""
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="hexactl-soak-") as directory, \
            MonitoredService(Path(directory), rate_hz) as harness:
        operator = harness.operator
        variants = calibration_variants(harness.geometry, seed, count=16)
        outcomes: Counter[str] = Counter()
        harness.ensure_enabled()
        harness.recoveries.clear()  # the first enable is the start, not a recovery
        harness.recovery_reasons.clear()
        before = harness.loop_figures()
        traffic = Traffic(harness, traffic_hz, seed + 1)
        traffic.start()
        start = time.monotonic()
        next_swap = start + swap_every_s
        next_progress = start + 60.0
        names = [*BUILTIN_SEQUENCES, "inline"]
        played = finished = swaps = saves = 0
        loaded = False
        try:
            while (now := time.monotonic()) < start + duration_s:
                harness.ensure_enabled()
                current = harness.status()
                if current["sequence"] is None and current["motion"] == "holding":
                    if played > saves:
                        saves += 1
                        reply = record(outcomes, operator, "save_recording", path=f"soak-{saves}.csv")
                        finished += bool(reply and reply["ok"] and reply["status"] == "finished")
                    name = names[played % len(names)]
                    sequence = inline_sequence(harness.geometry, rng, f"inline-{played}") if name == "inline" else name
                    if (reply := record(outcomes, operator, "play", sequence=sequence)) and reply["ok"]:
                        played += 1
                if now >= next_swap:
                    if loaded:
                        reply = record(outcomes, operator, "rollback_calibration")
                    else:
                        reply = record(outcomes, operator, "load_calibration", toml=variants[swaps % len(variants)])
                    if reply and reply["ok"]:
                        loaded = not loaded
                        swaps += 1
                    next_swap = now + swap_every_s
                if now >= next_progress:
                    loop = harness.status()["loop"]
                    progress(f"{(now - start) / 60:.1f} min: {played} sequences, {swaps} swaps, loop missed "
                             f"{loop['missed']}, recoveries {dict(harness.recoveries)}, "
                             f"monitor violations {harness.monitor_figures()['violations']}")
                    next_progress = now + 60.0
                time.sleep(0.05)
        finally:
            traffic.stop()
        after = harness.loop_figures()
        outcomes.update(traffic.outcomes)
        return {
            "seconds": round(time.monotonic() - start, 1),
            "rate_hz": rate_hz,
            "loop": loop_difference(before, after),
            "sequences_played": played,
            "sequences_finished": finished,
            "calibration_swaps": swaps,
            "telemetry_records": traffic.telemetry_records,
            "requests": dict(sorted(outcomes.items())),
            "requests_missing": sum(n for key, n in outcomes.items() if key.endswith(":missing")),
            "internal_errors": sum(n for key, n in outcomes.items() if key.endswith(":internal_error")),
            "recoveries": dict(harness.recoveries),
            "recovery_reasons": dict(harness.recovery_reasons.most_common()),
            "monitor": harness.monitor_figures(),
        }


def print_report(result: dict[str, Any]) -> None:
    loop, monitor = result["loop"], result["monitor"]
    print(f"soak: {result['seconds']} s at {result['rate_hz']} Hz")
    print(f"  loop: {loop['cycles']} cycles ({loop['achieved_rate_hz']} Hz achieved), missed {loop['missed']}, "
          f"skipped {loop['skipped']}, guard clamps {loop['guard_clamps']}")
    print(f"  lateness us (recent window): p50 {loop['lateness_us']['p50']:.1f} p99 {loop['lateness_us']['p99']:.1f} "
          f"p999 {loop['lateness_us']['p999']:.1f}; max over the run {loop['lateness_us']['max']:.1f}")
    print(f"  compute us (recent window): p50 {loop['compute_us']['p50']:.1f} p99 {loop['compute_us']['p99']:.1f}; "
          f"max over the run {loop['compute_us']['max']:.1f}; gc runs {loop['gc_runs']}, longest {loop['gc_max_us']:.1f} us")
    print(f"  sequences played {result['sequences_played']} (finished and saved {result['sequences_finished']}), "
          f"calibration swaps {result['calibration_swaps']}, telemetry records {result['telemetry_records']}")
    print(f"  requests: {sum(result['requests'].values())}, missing {result['requests_missing']}, "
          f"internal errors {result['internal_errors']}")
    for key, count in result["requests"].items():
        print(f"    {key:40s} {count}")
    print(f"  faults recovered: {result['recoveries'] or 'none'}")
    for reason, count in result["recovery_reasons"].items():
        print(f"    {count:5d} x {reason}")
    print(f"  monitor: {monitor['violations']} violations; {monitor['counts'].get('cycles', 0)} cycles, "
          f"{monitor['counts'].get('setpoints', 0)} set-points checked, late cycles {monitor['counts'].get('late_cycles', 0)}, "
          f"longest gap {monitor['max_cycle_gap_ms']} ms, largest step {monitor['max_step_fraction']:.3f} of the limit, "
          f"closest to a stroke end {monitor['min_stroke_margin_mm']} mm")
    for line in monitor["first_violations"]:
        print(f"    {line}")


def passed(result: dict[str, Any]) -> bool:
    """No limit violation on the bus, no request unanswered, no internal error."""
    return result["monitor"]["violations"] == 0 and result["requests_missing"] == 0 and result["internal_errors"] == 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--minutes", type=float, help="how long (default 10)")
    length.add_argument("--seconds", type=float, help="how long, in seconds")
    parser.add_argument("--rate", type=int, default=500, choices=(500, 1000), help="loop rate, Hz")
    parser.add_argument("--swap-every", type=float, default=5.0, help="seconds between calibration loads/rollbacks")
    parser.add_argument("--traffic-hz", type=float, default=20.0, help="status + validate_pose rate of the second client")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    arguments = parser.parse_args(argv)
    duration_s = arguments.seconds if arguments.seconds is not None else 60.0 * (arguments.minutes or 10.0)
    result = soak(duration_s, arguments.rate, arguments.swap_every, arguments.traffic_hz, arguments.seed,
                  progress=lambda line: print(line, flush=True))
    print_report(result)
    if arguments.json:
        arguments.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0 if passed(result) else 1


if __name__ == "__main__":
    sys.exit(main())
