"""The wave generator on the whole service (the API, the command line), watched by the
independent bus monitor: no set-point outside the stroke or the legs' speed during a
wave, played to the end or aborted mid-way (issue 12)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.cli.main import main
from hexactl.control.waves import WavePath, WaveSpec
from hexactl.kinematics.axes import RelativeMmRad
from tests.api.test_service import WAIT_S, status, wait_for
from tests.reliability.support import RATE_HZ, recover, tolerating_loop_stalls

ABORTED_CYCLES = 30
"""The wave the abort test ends: three requests go between its steady phase and the abort,
and a host that holds them up for seconds must not let the wave finish first (6 cycles,
at 1 Hz, left about 4 s for them)."""

WAVE = {"axes": {"z": {"amplitude": 2.0}, "roll": {"amplitude": 0.2, "phase_deg": 90}}, "frequency_hz": 1.0,
        "cycles": 3}


def test_a_wave_plays_every_phase_and_ends_at_rest_where_it_started(client: HexactlClient, service) -> None:
    def scenario() -> None:
        recover(client)
        start = status(client)["pose_command"]
        valid = client.call("validate_wave", **WAVE)
        assert valid["valid"] and valid["refusal"] is None
        reply = client.call("wave", **WAVE)
        assert reply["duration"] == 3.0 and reply["message"] == "waving"
        assert reply["peak_leg_speed_mm_s"] == pytest.approx(valid["wave"]["peak_leg_speed_mm_s"], rel=1e-9)
        assert 1 <= reply["peak_leg_speed_leg"] <= 6 and reply["peak_pose_velocity"][2] > 0
        phases = []
        while (record := status(client))["motion"] != "holding" or not phases:
            if record["wave"] and (not phases or phases[-1] != record["wave"]["phase"]):
                phases.append(record["wave"]["phase"])
            assert record["state"] == "enabled"
        final = status(client)
        assert final["wave"] == {"cycle": 3, "cycles": 3, "phase": "finished"}
        assert {"ramp_in", "steady", "ramp_out"} <= set(phases)  # a 3 s wave polled every few ms: each seen
        assert final["pose_command"] == pytest.approx(start, abs=1e-9)
        assert final["loop"]["guard_clamps"] == 0

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))


def test_abort_mid_wave_brakes_to_rest_and_a_pause_is_refused(client: HexactlClient, service) -> None:
    def scenario() -> None:
        recover(client)
        client.call("wave", **{**WAVE, "cycles": ABORTED_CYCLES})  # long: the abort comes mid-wave on a busy host too
        wait_for(lambda: (status(client)["wave"] or {}).get("phase") == "steady", "the steady phase")
        with pytest.raises(CommandError) as paused:
            client.call("pause")
        assert paused.value.code == "busy" and "abort" in str(paused.value)
        with pytest.raises(CommandError) as moved:
            client.call("move", pose=[0, 0, 10, 0, 0, 0])
        assert moved.value.code == "busy" and "wave is playing" in str(moved.value)
        client.call("abort")
        wait_for(lambda: status(client)["motion"] == "holding", "the halt")
        final = status(client)
        assert final["wave"]["phase"] == "aborted" and final["wave"]["cycle"] < ABORTED_CYCLES
        assert final["loop"]["guard_clamps"] == 0

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))


def test_the_command_line_validates_plays_waits_and_refuses(service, client: HexactlClient, capsys) -> None:
    def hexactl(*arguments: str) -> int:
        return main(["wave", *arguments, "--api", service.api_endpoint, "--timeout", str(WAIT_S)])

    def scenario() -> None:
        recover(client)
        capsys.readouterr()
        assert hexactl("--axis", "z:1", "--frequency", "1", "--cycles", "4", "--validate") == 0
        assert "ok: valid; 4.00 s; peak leg speed" in capsys.readouterr().out
        assert hexactl("--axis", "z:1", "--axis", "roll:0.1:90", "--frequency", "1", "--cycles", "3", "--wait") == 0
        assert status(client)["wave"]["phase"] == "finished"
        assert hexactl("--axis", "x:80", "--frequency", "1", "--cycles", "4") == 1
        assert "error planning_failed: the x velocity would reach" in capsys.readouterr().err

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))
    with pytest.raises(SystemExit):
        hexactl("--axis", "w:1", "--frequency", "1", "--cycles", "2")
    assert "AXIS one of x, y, z, roll, pitch, yaw" in capsys.readouterr().err


def test_a_recording_at_500_hz_during_a_wave_has_every_cycle(client: HexactlClient, service, data_dir) -> None:
    """Done-when: the data recorder at the loop's 500 Hz, armed for the next motion, keeps
    every cycle of a wave, and its commanded z is the wave's."""
    def scenario() -> None:
        recover(client)
        for leftover in data_dir.glob("wave500.*"):  # an earlier attempt's
            leftover.unlink()
        start_z = status(client)["pose_command"][2]
        armed = client.call("record", name="wave500", duration_s=2.0, start="next_motion",
                            signals=["pose_command", "setpoints"])
        assert (armed["rows"], armed["rate_hz"]) == (1000, 500.0)
        client.call("wave", axes={"z": {"amplitude": 2.0}}, frequency_hz=1.0, cycles=2)
        side = wait_for(lambda: (r := client.call("record_status"))["state"] == "done" and r, "the recording's file")
        assert (side["rows_written"], side["cycles_missing"], side["rows_lost"]) == (1000, 0, 0)
        with open(data_dir / "wave500.csv") as handle:
            table = list(csv.DictReader(handle))
        cycles = [int(row["cycle"]) for row in table]
        assert cycles == list(range(cycles[0], cycles[0] + 1000)), "a cycle is missing"
        z = np.array([float(row["pose_command_z_mm"]) for row in table]) - start_z
        # the wave's own samples: its first cycle is the recording's first row
        expected = [WavePath(WaveSpec(frequency_hz=1.0, cycles=2, axes={"z": {"amplitude": 2.0}}),
                             RelativeMmRad(*(0.0,) * 6), 1 / RATE_HZ).at(k)[2] for k in range(1, 1001)]
        assert np.max(np.abs(z - expected)) < 1e-6  # the CSV's precision
        assert np.max(z) == pytest.approx(max(expected), abs=1e-6) and np.max(z) > 1.5  # its peak recorded
        wait_for(lambda: status(client)["motion"] == "holding", "the wave's end")

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))
