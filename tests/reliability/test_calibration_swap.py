"""Calibration swaps under motion, on the whole service: 100 swaps while a sequence plays,
good and bad files mixed. The bad ones are refused with their code, the good ones ramped
in without a set-point step beyond the velocity limit (the bus monitor), and the loop's
missed cycles are reported beside a baseline run of the same length without swaps (run
with ``-s`` to see them; they depend on the machine, so they are not asserted)."""

from __future__ import annotations

import random
import time
from pathlib import Path


from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import status, wait_for
from tests.reliability.support import recover, tolerating_loop_stalls
from tools.soak import OUTSIDE_FILE, bad_calibrations

SWAPS = 100
SWAP_INTERVAL_S = 0.05  # one swap every 50 ms (an operator swaps far less often): 5 s of swapping
TOUR = {"name": "swap_tour", "waypoints": [
    {"pose": [0, 0, 40, 0, 0, 0], "dwell": 0.05}, {"pose": [30, 0, -20, 0, 2, 0], "dwell": 0.05},
    {"pose": [-30, 20, 0, 2, 0, -3], "dwell": 0.05}, {"pose": [0, -20, 20, 0, -2, 3], "dwell": 0.05},
    {"pose": [0, 0, 0, 0, 0, 0], "dwell": 0.05},
]}


def variant(geometry: Geometry, name: str, **changes: object) -> Geometry:
    """``geometry`` with top-level keys (or ``limits`` keys) replaced."""
    data = geometry.model_dump()
    limits = changes.pop("limits", {})
    data.update(changes, name=name)
    data["limits"] = {**data["limits"], **limits}
    return Geometry.model_validate(data)


def good_calibration(nominal: Geometry, rng: random.Random, index: int) -> Geometry:
    """A plausible identification: zero lengths off by up to 2 mm, base joints by up to 1 mm."""
    zero = [length + rng.uniform(-2.0, 2.0) for length in nominal.zero_lengths]
    base = [[c + rng.uniform(-1.0, 1.0) for c in joint] for joint in nominal.base_joints]
    return variant(nominal, f"good {index}", zero_lengths=zero, base_joints=base)


def playing(client: HexactlClient) -> None:
    """Keep the tour playing: start it again whenever it has finished."""
    record = status(client)
    assert record["state"] == "enabled", record["faults"]
    if record["sequence"] is None and record["motion"] == "holding":
        client.call("play", sequence=TOUR)


def load(client: HexactlClient, fields: dict[str, str]) -> dict:
    """``load_calibration``'s reply, asked again after a ``stale_plan`` (nothing here stops):
    the motion went on to its next segment, or the tour began again, while the swap's ramp
    was planned (on a loaded host the API plans from an older snapshot)."""
    return wait_for(lambda: None if (reply := client.request("load_calibration", **fields)).get("error", {}).get("code")
                    == "stale_plan" else reply, "a swap not refused stale_plan")


def missed_during(client: HexactlClient, seconds: float | None, work) -> tuple[int, float]:
    """(missed cycles, seconds) while ``work()`` runs, or for ``seconds`` of playing alone."""
    before = status(client)
    started = time.monotonic()
    if work is not None:
        work()
    while seconds is not None and time.monotonic() < started + seconds:
        playing(client)
        time.sleep(0.02)
    after = status(client)
    return after["loop"]["missed"] - before["loop"]["missed"], after["t"] - before["t"]


def test_100_swaps_during_playback(client, monitor, service, nominal, data_dir: Path) -> None:
    rng = random.Random(7)
    bad = bad_calibrations(nominal)
    swaps: list[tuple[dict[str, str], tuple[str, ...]]] = []
    good_ids: list[str] = []
    for index in range(SWAPS):
        if index % 2:
            swaps.append(bad[index // 2 % len(bad)])
            continue
        good = good_calibration(nominal, rng, index)
        good_ids.append(geometry_id(good))
        if index % 4:
            (data_dir / f"good-{index}.toml").write_text(geometry_to_toml(good))
            swaps.append(({"path": f"good-{index}.toml"}, (geometry_id(good),)))
        else:
            swaps.append(({"toml": geometry_to_toml(good)}, (geometry_id(good),)))
    (data_dir.parent / OUTSIDE_FILE).write_text(geometry_to_toml(nominal))

    def scenario() -> None:
        recover(client)
        clamps = status(client)["loop"]["guard_clamps"]
        client.call("play", sequence=TOUR)
        outcomes: list[tuple[str, str]] = []

        def swap_all() -> None:
            for fields, expected in swaps:
                due = time.monotonic() + SWAP_INTERVAL_S
                playing(client)
                reply = load(client, fields)
                outcomes.append((reply["calibration_id"] if reply["ok"] else reply["error"]["code"], expected))
                time.sleep(max(0.0, due - time.monotonic()))

        missed, seconds = missed_during(client, None, swap_all)
        baseline_missed, baseline_seconds = missed_during(client, seconds, None)
        print(f"\n{SWAPS} swaps in {seconds:.2f} s: loop missed {missed} cycles; "
              f"baseline without swaps, {baseline_seconds:.2f} s: missed {baseline_missed}")

        assert [(index, got, expected) for index, (got, expected) in enumerate(outcomes) if got not in expected] == []
        record = status(client)
        assert record["state"] == "enabled" and record["calibration_id"] == good_ids[-1]  # the last good one
        assert record["loop"]["guard_clamps"] == clamps  # every ramp fitted in its share of the velocity limit
        client.request("abort")  # the tour may have just ended (no_sequence)
        wait_for(lambda: status(client)["motion"] == "holding", "the tour to stop")

    tolerating_loop_stalls(scenario, lambda: service.controller)
    monitor.catch_up()
    assert monitor.counts["cycles"] > 0 and monitor.report().max_step_fraction <= 1.0


def test_a_calibration_cannot_widen_the_actuators_limits(client, nominal) -> None:
    recover(client)
    low, high = nominal.limits.stroke
    wide = variant(nominal, "wide", limits={"stroke": [low - 100.0, high + 100.0],
                                            "leg_velocity_mm_s": 2 * nominal.limits.leg_velocity_mm_s})
    reply = client.request("load_calibration", toml=geometry_to_toml(wide))
    if reply["ok"]:
        client.call("rollback_calibration")
    assert not reply["ok"]
