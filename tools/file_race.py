#!/usr/bin/env python3
"""Race file swaps against ``load_calibration`` on a real ``hexactl serve`` (hexactl issue
10, findings 1 and 2) and time ``estop`` meanwhile.

    python tools/file_race.py --seconds 30          # the figures in BENCHMARKS.md
    python tools/file_race.py --seconds 5 --json race.json

What runs: ``hexactl serve`` on its simulator, in a temporary working directory (so its
data directories are ``./calibrations`` and the others by default), on random loopback
ports. A separate process (the attacker: anyone who can write into a data directory)
rename-swaps a valid calibration file, a FIFO and a symlink to a valid calibration
*outside* the data directories onto ``calibrations/race.toml``, one after the other as
fast as it can. A client repeats ``load_calibration`` of ``race.toml`` all the while
(for ``--seconds``, and on until one load succeeded and one met a FIFO or symlink);
every ``--estop-every`` seconds a new client sends ``estop``, timed from its creation to
the answer, then reads ``status`` and sends ``reset``. At the end the service gets
SIGTERM and must exit, leaving both its ports free.

It prints the loads by outcome (``loaded`` or the error code; ``no_answer`` when the
client timed out), how many loaded the outside file, the E-stop latencies (p50, p99,
max) and states, and how the service shut down. Exit status 0 when every request was
answered, none with ``internal_error``, none loaded the outside file, some loaded the
inside one, every E-stop latched, and the service exited on SIGTERM (status 0, within
10 s) with its ports free;
1 otherwise. Latencies are reported, not judged: they depend on the machine.

:func:`race` is what ``tests/reliability/test_file_race.py`` runs.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from multiprocessing.sharedctypes import Synchronized
from multiprocessing.synchronize import Event
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # noqa: E402
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry  # noqa: E402
from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from tools.serving import Shutdown, serve, terminate  # noqa: E402

RACE_NAME = "race.toml"
ANSWER_TIMEOUT_S = 5.0
"""How long a client waits for any answer: far above any healthy one, so that only a
blocked API goes unanswered."""
ATTACKER_TIMEOUT_S = 60.0
"""How long the swapping process may take to start or to stop."""
LONGEST_RACE_FACTOR = 10.0


@dataclass(frozen=True)
class RaceFiles:
    """The files of a race in ``directory``: ``calibrations/race.toml`` is swapped between
    a hard link to ``inside`` (a valid calibration), a FIFO and a symlink to ``outside``
    (another valid calibration, outside every data directory, with another id)."""

    directory: Path
    inside: Path
    outside: Path
    inside_id: str
    outside_id: str

    @property
    def race(self) -> Path:
        return self.directory / "calibrations" / RACE_NAME

    @classmethod
    def create(cls, directory: Path) -> RaceFiles:
        nominal = load_geometry(default_config_path())
        (directory / "calibrations").mkdir(exist_ok=True)
        # Zero lengths 0.1 and 0.2 mm off: two plausible calibrations with distinct ids.
        inside, outside = (nominal.model_copy(update={"name": name, "zero_lengths": tuple(z + offset for z in nominal.zero_lengths)})
                           for name, offset in (("inside", 0.1), ("outside", 0.2)))
        files = cls(directory, directory / "calibrations" / "inside.toml", directory / "outside.toml",
                    geometry_id(inside), geometry_id(outside))
        files.inside.write_text(geometry_to_toml(inside))
        files.outside.write_text(geometry_to_toml(outside))
        return files


def _swap(files: RaceFiles, started: Event, stop: Event, swaps: Synchronized[int]) -> None:
    """The attacker: rename-swap a regular file, a FIFO and a symlink to the outside file
    onto the race name, in turn, from ``started`` until ``stop``; the count in ``swaps``."""
    staged = files.race.with_name(".race.next")
    count = 0
    started.set()
    while not stop.is_set():
        for make in (lambda: os.link(files.inside, staged), lambda: os.mkfifo(staged),
                     lambda: os.symlink(files.outside, staged)):
            make()
            os.rename(staged, files.race)
            count += 1
    swaps.value = count


@contextmanager
def swapping(files: RaceFiles) -> Iterator[Synchronized[int]]:
    """The attacker's process, swapping while inside the ``with``; yields its swap count
    (set when it has stopped)."""
    context = multiprocessing.get_context("spawn")
    started, stop, swaps = context.Event(), context.Event(), context.Value("q", 0)
    attacker = context.Process(target=_swap, args=(files, started, stop, swaps), name="file-race-attacker", daemon=True)
    attacker.start()
    try:
        if not started.wait(ATTACKER_TIMEOUT_S):
            raise RuntimeError("the swapping process did not start")
        yield swaps
    finally:
        stop.set()
        attacker.join(ATTACKER_TIMEOUT_S)
        if attacker.is_alive():
            attacker.kill()
            raise RuntimeError("the swapping process did not stop")


@dataclass
class RaceResult:
    """What the clients saw during a race."""

    loads: Counter[str] = field(default_factory=Counter)
    """By outcome: ``loaded`` (the inside file), ``loaded_outside`` (a leak), an error
    code, or ``no_answer``."""
    other_answers: Counter[str] = field(default_factory=Counter)
    """The E-stop clients' other requests (status, reset) by the same outcomes."""
    estop_latencies_s: list[float] = field(default_factory=list)
    """From creating the new client to its ``estop`` answer, for each answered one (the
    others count in ``estop_unanswered``)."""
    estop_states: list[str] = field(default_factory=list)
    """The state ``status`` showed after each answered E-stop."""
    estop_unanswered: int = 0
    swaps: int = 0


def race(files: RaceFiles, api: str, seconds: float, estop_every_s: float, min_loaded: int = 1) -> RaceResult:
    """Swap files onto ``race.toml`` while loading it over and over, with a new client's
    ``estop`` (then ``status`` and ``reset``) every ``estop_every_s``: for ``seconds`` from
    the first swap, and on until ``min_loaded`` loads of the inside file succeeded and one
    met a swapped-in FIFO or symlink (at most :data:`LONGEST_RACE_FACTOR` times as long: on
    a busy host loads are few)."""
    result = RaceResult()
    racing = threading.Event()
    racing.set()

    def racing_on() -> bool:
        elapsed = time.monotonic() - started
        both_ways = result.loads["loaded"] >= min_loaded and result.loads["file_not_found"] > 0
        return elapsed < seconds or (not both_ways and elapsed < LONGEST_RACE_FACTOR * seconds)

    def load_repeatedly() -> None:
        with HexactlClient(api, timeout_s=ANSWER_TIMEOUT_S) as client:
            while racing.is_set():
                result.loads[_outcome(client, files, "load_calibration", path=RACE_NAME)] += 1

    with swapping(files) as swaps:
        started = time.monotonic()  # not before: the attacker's process takes seconds to start on a busy host
        loader = threading.Thread(target=load_repeatedly, name="file-race-loader")
        loader.start()
        try:
            while racing_on():
                time.sleep(estop_every_s)
                _estop_round(api, result)
        finally:
            racing.clear()
            loader.join(ANSWER_TIMEOUT_S * 2)
    result.swaps = swaps.value
    if loader.is_alive():
        result.loads["loader_stuck"] += 1
    return result


def _estop_round(api: str, result: RaceResult) -> None:
    started = time.perf_counter()
    with HexactlClient(api, timeout_s=ANSWER_TIMEOUT_S) as client:
        try:
            reply = client.request("estop")
        except ServiceUnavailable:
            result.estop_unanswered += 1
            return
        result.estop_latencies_s.append(time.perf_counter() - started)
        if not reply.get("ok"):
            result.other_answers[f"estop_{reply['error']['code']}"] += 1
        else:
            result.other_answers["estop_ok"] += 1
        try:
            result.estop_states.append(client.call("status")["status"]["state"])
        except Exception as error:  # noqa: BLE001 - counted: a status must be answered too
            result.other_answers[f"status_{type(error).__name__}"] += 1
        result.other_answers[_outcome(client, None, "reset")] += 1  # so the next E-stop latches anew


def _outcome(client: HexactlClient, files: RaceFiles | None, cmd: str, **fields: object) -> str:
    try:
        reply = client.request(cmd, **fields)
    except ServiceUnavailable:
        return "no_answer"
    if not reply.get("ok"):
        return reply["error"]["code"]
    if files is not None and reply.get("calibration_id") == files.outside_id:
        return "loaded_outside"
    if files is None:
        return f"{cmd}_ok"
    return "loaded" if reply.get("calibration_id") == files.inside_id else "loaded_unknown"


def problems(result: RaceResult, shutdown: Shutdown) -> list[str]:
    """Every way the run failed the promise (empty: it kept it)."""
    found = []
    for outcome in ("no_answer", "loader_stuck", "internal_error", "loaded_outside", "loaded_unknown"):
        if result.loads[outcome] or result.other_answers[outcome]:
            found.append(f"{result.loads[outcome] + result.other_answers[outcome]} requests: {outcome}")
    if not result.loads["loaded"]:
        found.append("no load of the inside file succeeded (a fix that refuses everything?)")
    if result.estop_unanswered or not result.estop_latencies_s:
        found.append(f"{result.estop_unanswered} of {result.estop_unanswered + len(result.estop_latencies_s)} E-stops unanswered")
    if any(state != "estop" for state in result.estop_states) or len(result.estop_states) != len(result.estop_latencies_s):
        found.append(f"E-stop did not latch every time: states {result.estop_states}")
    return found + shutdown.problems()


def percentile(values: list[float], fraction: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(fraction * (len(ordered) - 1)))]


def report(result: RaceResult, shutdown: Shutdown) -> str:
    latencies_ms = [1000.0 * s for s in result.estop_latencies_s] or [float("nan")]
    lines = [
        f"swaps: {result.swaps} (file, FIFO, symlink to outside, in turn)",
        "loads: " + ", ".join(f"{outcome} {count}" for outcome, count in result.loads.most_common()),
        "other answers: " + ", ".join(f"{outcome} {count}" for outcome, count in result.other_answers.most_common()),
        f"estop latency ms (new client, {len(result.estop_latencies_s)} answered, {result.estop_unanswered} unanswered): "
        f"p50 {percentile(latencies_ms, 0.5):.1f}, p99 {percentile(latencies_ms, 0.99):.1f}, max {max(latencies_ms):.1f}",
        f"estop states: {dict(Counter(result.estop_states))}",
        str(shutdown),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="how long to race (default 10)")
    parser.add_argument("--estop-every", type=float, default=0.25, metavar="S", help="seconds between E-stops (default 0.25)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="file_race_") as directory:
        files = RaceFiles.create(Path(directory))
        with serve(files.directory) as served:
            result = race(files, served.api, arguments.seconds, arguments.estop_every)
            shutdown = terminate(served)
    print(report(result, shutdown))
    found = problems(result, shutdown)
    for problem in found:
        print(f"FAILED: {problem}")
    if arguments.json:
        latencies_ms = [1000.0 * s for s in result.estop_latencies_s]
        figures = {
            "swaps": result.swaps, "loads": dict(result.loads), "other_answers": dict(result.other_answers),
            "estop_latency_ms": {"answered": len(latencies_ms), "unanswered": result.estop_unanswered,
                                 **({"p50": percentile(latencies_ms, 0.5), "p99": percentile(latencies_ms, 0.99),
                                     "max": max(latencies_ms)} if latencies_ms else {})},
            "estop_states": dict(Counter(result.estop_states)), "shutdown": asdict(shutdown), "problems": found,
        }
        arguments.json.write_text(json.dumps(figures, indent=2))
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
