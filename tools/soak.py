#!/usr/bin/env python3
"""Soak the whole service: sequences played back to back with API traffic beside them,
for ``--minutes`` at ``--rate`` Hz, every set-point checked by an independent bus monitor.

    python tools/soak.py --minutes 10 --fifo 80 --mlock   # the figures in BENCHMARKS.md
    python tools/soak.py --minutes 10                     # normal scheduling
    python tools/soak.py --seconds 20 --json soak.json

What runs, in a child process: ``Service.start`` on its simulator (six simulated actuator
firmwares on a private ``virtual:`` bus) and a
:class:`~hexactl.adapters.can.bus_monitor.BusMonitor` on that bus. The operator (this
process's main thread) keeps the platform enabled and playing: the built-in sequences and a seeded
inline one in turn, each saved with ``save_recording`` when it ends; every
``--swap-every`` seconds it loads a calibration variant (zero lengths off by up to 1 mm),
sends a bad one (:func:`bad_calibrations`: it must be refused with its code), rolls the
variant back, sends another bad one, and so on, while the sequence plays. A second client, in its own thread, asks
``status`` and ``validate_pose`` (a random pose in the envelope) at ``--traffic-hz``, and
a telemetry subscriber reads every record.

It reports the loop's figures (cycles, achieved rate, missed and skipped cycles, lateness
and compute percentiles over the loop's recent window and the maxima over the run, GC,
guard clamps), the requests by command and outcome, the faults the controller latched
(each recovered with ``reset`` and ``enable``, and counted), and the monitor's counts.

``--fifo PRIO`` and ``--mlock`` run the service's process as ``hexactl serve`` runs with
them (the bus monitor's thread, which shares the loop's GIL, one below the loop).

Exit status 0 when the monitor saw no violation, every request was answered, none
failed with ``internal_error`` and every bad calibration was refused with its code; 1 otherwise. Missed cycles and faults are reported, not
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
from dataclasses import asdict, dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from types import TracebackType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber  # noqa: E402
from hexactl.adapters.can.bus_monitor import MONITOR_THREAD_NAME, BusMonitor  # noqa: E402
from hexactl.adapters.files.geometry_file import geometry_to_toml, load_geometry  # noqa: E402
from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.application.service import Service, ServiceConfig, ServiceError, fifo_below_loop  # noqa: E402
from hexactl.application.spawned import STOP, Spawned, SpawnError  # noqa: E402
from hexactl.control.sequences import BUILTIN_SEQUENCES  # noqa: E402
from hexactl.kinematics.geometry import Geometry  # noqa: E402

LOCAL = "tcp://127.0.0.1:*"
REQUEST_TIMEOUT_S = 30.0  # generous: a loaded machine; a request unanswered this long counts as missing
ENABLE_TIMEOUT_S = 30.0
RESET_RETRY_S = 0.1  # a reset's CLEAR_FAULT may wait for the actuators' E-stop hold-off (0.3 s)
ENVELOPE_FRACTION = 0.5  # random poses stay within this share of the pose envelope
START_TIMEOUT_S = 60.0
MONITOR = "monitor"  # the request for the monitor's figures


@dataclass(frozen=True)
class Scheduling:
    """How the service's process runs (``hexactl serve --fifo/--mlock``): ``fifo_priority``
    SCHED_FIFO for the loop thread, one below for the simulator's and the bus monitor's
    threads (None: normal scheduling); ``lock_memory``: mlockall."""

    fifo_priority: int | None = None
    lock_memory: bool = False


class MonitoredService:
    """The service on its simulator with a bus monitor on its bus from before the first
    enable, both in a child process of their own (as ``hexactl serve`` would run, so
    that this process's work, e.g. hypothesis generating requests, never holds the loop's
    GIL), and an operator client here; a context manager.

    ``data_dir``: the service's only data directory.
    """

    def __init__(self, data_dir: Path, rate_hz: int = 500, config_path: Path | None = None,
                 scheduling: Scheduling = Scheduling()) -> None:
        self.data_dir = data_dir
        self.rate_hz = rate_hz
        self.geometry = load_geometry(config_path or default_config_path())
        config = ServiceConfig(config_path=config_path, api_endpoint=LOCAL, telemetry_endpoint=LOCAL,
                               data_dirs=(data_dir,), rate_hz=rate_hz, log_level="WARNING",
                               kept_calibration_path=data_dir / "active_calibration.toml",  # not the caller's
                               fifo_priority=scheduling.fifo_priority, lock_memory=scheduling.lock_memory)
        try:
            self._child = Spawned(_serve_monitored, (config, self.geometry), name="monitored service", daemon=False,
                                  start_timeout_s=START_TIMEOUT_S)  # fmt: skip
        except SpawnError as error:
            raise SystemExit(f"the service did not start: {error}") from None
        self.api_endpoint, self.telemetry_endpoint, self.realtime = self._child.served
        """``realtime``: what the loop's thread obtained (:class:`~hexactl.control.realtime.RealtimeReport` as a dict)."""
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
            if reply["ok"]:
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
    if config.fifo_priority is not None:  # the monitor's reader shares the loop's GIL, as the simulator's does
        fifo_below_loop(config.fifo_priority, {MONITOR_THREAD_NAME})
    try:
        realtime = asdict(service.controller.thread.loop.realtime)
        control.send((service.api_endpoint, service.telemetry_endpoint, realtime))
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


OUTSIDE_FILE = "outside.toml"
"""A valid calibration beside (not in) the data directory, for :func:`bad_calibrations`."""


def bad_calibrations(geometry: Geometry) -> list[tuple[dict[str, str], tuple[str, ...]]]:
    """``load_calibration`` requests the service must refuse: (request fields, the error
    codes it may give). Texts broken in five ways, a change too large to ramp (a zero
    length 40 mm off: ``invalid_geometry`` instead where the platform is near the limits,
    since the ramp to it would leave them, which is checked first), a path out of the data
    directory (to :data:`OUTSIDE_FILE`, which should exist beside it) and one to no file."""
    text = geometry_to_toml(geometry)
    zero = geometry.zero_lengths
    far = geometry.model_copy(update={"name": "40 mm off", "zero_lengths": (zero[0] + 40.0, *zero[1:])})
    return [
        ({"toml": text[: len(text) // 2]}, ("invalid_calibration",)),  # cut short
        ({"toml": text.replace(f"zero_lengths = [{zero[0]!r}", "zero_lengths = [nan", 1)}, ("invalid_calibration",)),
        ({"toml": "\n".join(line for line in text.splitlines() if not line.startswith("home"))},
         ("invalid_calibration",)),
        ({"toml": text + "\nsurprise = 1\n"}, ("invalid_calibration",)),
        ({"toml": text.replace("stroke = [0.0, 850.0]", "stroke = [0.0, 100.0]")}, ("invalid_calibration",)),
        ({"toml": geometry_to_toml(far)}, ("calibration_change_too_large", "invalid_geometry")),
        ({"path": f"../{OUTSIDE_FILE}"}, ("forbidden_path",)),
        ({"path": "missing.toml"}, ("file_not_found",)),
    ]


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


class CalibrationSwaps:
    """The soak's calibration changes, one per :meth:`swap`: in turn a good variant loaded,
    a bad request, a rollback, a bad request, … The good ones count in :attr:`swaps` when
    applied; a bad one must be refused with its code, else it counts in :attr:`bad_wrong`."""

    def __init__(self, client: HexactlClient, variants: list[str],
                 bad: list[tuple[dict[str, str], tuple[str, ...]]]) -> None:
        self.client, self.variants, self.bad = client, variants, bad
        self.swaps = self.bad_sent = self.bad_wrong = 0
        self._loaded = self._bad_turn = False

    def swap(self, outcomes: Counter[str]) -> None:
        if self._bad_turn:
            fields, codes = self.bad[self.bad_sent % len(self.bad)]
            reply = record(outcomes, self.client, "load_calibration", **fields)
            self.bad_sent += 1
            self.bad_wrong += bool(reply and (reply["ok"] or reply["error"]["code"] not in codes))
        else:
            if self._loaded:
                reply = record(outcomes, self.client, "rollback_calibration")
            else:
                reply = record(outcomes, self.client, "load_calibration", toml=self.variants[self.swaps % len(self.variants)])
            if reply and reply["ok"]:
                self._loaded = not self._loaded
                self.swaps += 1
        self._bad_turn = not self._bad_turn


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
         progress: Callable[[str], None] = lambda line: None, scheduling: Scheduling = Scheduling()) -> dict[str, Any]:
    """Run the soak; the figures (see the module docstring)."""
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="hexactl-soak-") as directory:
        data = Path(directory) / "data"
        data.mkdir()
        with MonitoredService(data, rate_hz, scheduling=scheduling) as harness:
            return _soak(harness, duration_s, swap_every_s, traffic_hz, rng, seed, progress)


def _soak(harness: MonitoredService, duration_s: float, swap_every_s: float, traffic_hz: float, rng: random.Random,
          seed: int, progress: Callable[[str], None]) -> dict[str, Any]:
    """:func:`soak` on a running ``harness``."""
    operator = harness.operator
    (harness.data_dir.parent / OUTSIDE_FILE).write_text(geometry_to_toml(harness.geometry))
    swapper = CalibrationSwaps(operator, calibration_variants(harness.geometry, seed, count=16),
                               bad_calibrations(harness.geometry))
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
    played = finished = saves = 0
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
                swapper.swap(outcomes)
                next_swap = now + swap_every_s
            if now >= next_progress:
                loop = harness.status()["loop"]
                progress(f"{(now - start) / 60:.1f} min: {played} sequences, {swapper.swaps} swaps, loop missed "
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
        "rate_hz": harness.rate_hz,
        "realtime": harness.realtime,
        "loop": loop_difference(before, after),
        "sequences_played": played,
        "sequences_finished": finished,
        "calibration_swaps": swapper.swaps,
        "bad_calibrations_sent": swapper.bad_sent,
        "bad_calibrations_not_refused_as_expected": swapper.bad_wrong,
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
    print(f"soak: {result['seconds']} s at {result['rate_hz']} Hz; {realtime_line(result['realtime'])}")
    print(f"  loop: {loop['cycles']} cycles ({loop['achieved_rate_hz']} Hz achieved), missed {loop['missed']}, "
          f"skipped {loop['skipped']}, guard clamps {loop['guard_clamps']}")
    print(f"  lateness us (recent window): p50 {loop['lateness_us']['p50']:.1f} p99 {loop['lateness_us']['p99']:.1f} "
          f"p999 {loop['lateness_us']['p999']:.1f}; max over the run {loop['lateness_us']['max']:.1f}")
    print(f"  compute us (recent window): p50 {loop['compute_us']['p50']:.1f} p99 {loop['compute_us']['p99']:.1f}; "
          f"max over the run {loop['compute_us']['max']:.1f}; gc runs {loop['gc_runs']}, longest {loop['gc_max_us']:.1f} us")
    print(f"  sequences played {result['sequences_played']} (finished and saved {result['sequences_finished']}), "
          f"calibration swaps {result['calibration_swaps']}, bad calibrations sent {result['bad_calibrations_sent']} "
          f"(not refused as expected: {result['bad_calibrations_not_refused_as_expected']}), "
          f"telemetry records {result['telemetry_records']}")
    print(f"  requests: {sum(result['requests'].values())}, missing {result['requests_missing']}, "
          f"internal errors {result['internal_errors']}")
    for key, count in result["requests"].items():
        print(f"    {key:40s} {count}")
    print(f"  faults recovered: {result['recoveries'] or 'none'}")
    for reason, count in result["recovery_reasons"].items():
        print(f"    {count:5d} x {reason}")
    print_monitor(monitor)


def print_monitor(monitor: dict[str, Any]) -> None:
    """The bus monitor's figures (:meth:`MonitoredService.monitor_figures`), a line and its first violations."""
    print(f"  monitor: {monitor['violations']} violations; {monitor['counts'].get('cycles', 0)} cycles, "
          f"{monitor['counts'].get('setpoints', 0)} set-points checked, late cycles {monitor['counts'].get('late_cycles', 0)}, "
          f"longest gap {monitor['max_cycle_gap_ms']} ms, largest step {monitor['max_step_fraction']:.3f} of the limit, "
          f"closest to a stroke end {monitor['min_stroke_margin_mm']} mm")
    for line in monitor["first_violations"]:
        print(f"    {line}")


def passed(result: dict[str, Any]) -> bool:
    """No limit violation on the bus, no request unanswered, no internal error, every bad
    calibration refused with its code."""
    return (result["monitor"]["violations"] == 0 and result["requests_missing"] == 0 and result["internal_errors"] == 0
            and result["bad_calibrations_not_refused_as_expected"] == 0)


def add_service_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments every tool running a :class:`MonitoredService` takes: rate, scheduling
    (:func:`scheduling_from`), where to write the figures (:func:`conclude`), and a seed."""
    parser.add_argument("--rate", type=int, default=500, choices=(500, 1000), help="loop rate, Hz")
    parser.add_argument("--fifo", type=int, choices=range(2, 100), metavar="PRIO",
                        help="run the service's loop under SCHED_FIFO PRIO, as 'hexactl serve --fifo PRIO' does (the bus "
                             "monitor one below the loop; default: normal scheduling, as 'hexactl serve --no-realtime')")
    parser.add_argument("--mlock", action="store_true",
                        help="lock the service's memory, as 'hexactl serve' does by default (default: not locked, "
                             "as 'hexactl serve --no-realtime')")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="also write the figures here")


def scheduling_from(arguments: argparse.Namespace) -> Scheduling:
    return Scheduling(fifo_priority=arguments.fifo, lock_memory=arguments.mlock)


def realtime_line(realtime: dict[str, Any]) -> str:
    """What the loop obtained, in a few words, e.g. 'SCHED_FIFO 80, memory locked'."""
    fifo = f"SCHED_FIFO {realtime['fifo_priority']}" if realtime["fifo_priority"] else "normal scheduling"
    return fifo + (", memory locked" if realtime["memory_locked"] else "") + "".join(
        f"; {note}" for note in realtime["notes"])


def conclude(result: dict[str, Any], arguments: argparse.Namespace, report: Callable[[dict[str, Any]], None],
             judge: Callable[[dict[str, Any]], bool]) -> int:
    """Print the report, write the figures to ``--json``; the exit status: 0 if ``judge`` passes them."""
    report(result)
    if arguments.json:
        arguments.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0 if judge(result) else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--minutes", type=float, help="how long (default 10)")
    length.add_argument("--seconds", type=float, help="how long, in seconds")
    parser.add_argument("--swap-every", type=float, default=5.0, help="seconds between calibration loads/rollbacks")
    parser.add_argument("--traffic-hz", type=float, default=20.0, help="status + validate_pose rate of the second client")
    add_service_arguments(parser)
    arguments = parser.parse_args(argv)
    duration_s = arguments.seconds if arguments.seconds is not None else 60.0 * (arguments.minutes or 10.0)
    result = soak(duration_s, arguments.rate, arguments.swap_every, arguments.traffic_hz, arguments.seed,
                  progress=lambda line: print(line, flush=True), scheduling=scheduling_from(arguments))
    return conclude(result, arguments, print_report, passed)


if __name__ == "__main__":
    sys.exit(main())
