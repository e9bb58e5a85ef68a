"""The data recorder through the whole service: the loop in this process, the API and the
writer in theirs, the rows crossing with the loop's reports. A recording at the loop's
rate during a motion has every cycle."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator

import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.api.messages import RecordReply, RecordStatusReply, RecordStopReply, RecordingSideFile
from hexactl.application.service import ServiceConfig
from tests.api.support import service_here
from tests.api.test_service import WAIT_S, wait_for
from tests.reliability.support import tolerating_stalls


def status(client: HexactlClient) -> dict:
    return client.call("status")["status"]


def at_rest(client: HexactlClient) -> bool:
    record = status(client)
    assert record["state"] == "enabled", f"{record['state']} latched: {record['faults']}"
    return record["motion"] == "holding"


@pytest.fixture
def client(running) -> Iterator[HexactlClient]:
    with HexactlClient(running.api_endpoint, timeout_s=WAIT_S) as client:
        if status(client)["state"] != "enabled":
            client.call("enable")
        yield client


def finished(client: HexactlClient) -> dict:
    """The side file once the writer has finished the recording."""
    reply = wait_for(lambda: (r := client.call("record_status"))["state"] == "done" and r, "the recording's file")
    RecordStatusReply.model_validate(reply)
    return reply


def test_a_recording_at_the_loop_rate_during_a_motion_has_every_cycle(client, data_dir) -> None:
    def scenario() -> None:
        wait_for(lambda: at_rest(client), "rest")
        reply = client.call("record", name="moving", duration_s=1.0, start="next_motion")
        RecordReply.model_validate(reply)
        assert (reply["rows"], reply["rate_hz"]) == (500, 500.0)
        assert reply["path"] == str(data_dir / "moving.csv")
        assert status(client)["recording"]["state"] == "armed"
        moved = client.request("move", pose=[0, 0, 5, 0, 0, 1], duration=0.6)
        assert moved["ok"], moved  # a stall's fault: tolerated, tried again
        side = finished(client)
        client.request("move", pose=[0] * 6, duration=0.5)
        with open(data_dir / "moving.csv") as handle:
            table = list(csv.DictReader(handle))
        cycles = [int(row["cycle"]) for row in table]
        assert len(cycles) == 500 and cycles == list(range(cycles[0], cycles[0] + 500)), "a cycle is missing"
        assert {"t_s", "pose_command_z_mm", "pose_measured_yaw_deg", "setpoint_6_mm", "feedback_1_mm", "lateness_us",
                "compute_us"} <= set(table[0])
        assert float(table[0]["pose_command_z_mm"]) < 0.01 < float(table[-1]["pose_command_z_mm"])
        assert all(row["pose_measured_z_mm"] for row in table), "a row without its measured pose"
        written = json.loads((data_dir / "moving.json").read_text())
        RecordingSideFile.model_validate(written)
        assert (written["rows_written"], written["cycles_missing"], written["rows_lost"], written["ended"]) == \
            (500, 0, 0, "duration")
        assert written["start"] == "next_motion" and side["csv"] == str(data_dir / "moving.csv")
        assert not (data_dir / "moving.csv.partial").exists()
        assert status(client)["recording"] == {"state": "done", "name": "moving", "rows": 500, "rows_requested": 500,
                                               "lost": 0, "ended": "duration",
                                               "file": {"ended": "duration", "faults_during": False}}

    def cleanup() -> None:  # a retry records anew: a recording never overwrites
        if client.call("record_status")["state"] == "writing":
            client.call("record_stop")
        for made in ("moving.csv", "moving.json"):
            (data_dir / made).unlink(missing_ok=True)

    tolerating_stalls(client, scenario, cleanup)


def test_stop_ends_early_and_refusals_name_the_problem(client, data_dir) -> None:
    reply = client.call("record", name="long", duration_s=600, signals=["lateness", "compute"], divisor=5)
    assert reply["rate_hz"] == 100.0
    with pytest.raises(CommandError, match="'long' is under way.*stop it") as busy:
        client.call("record", name="other", duration_s=1)
    assert busy.value.code == "busy"
    wait_for(lambda: client.call("record_status").get("rows_written", 0) >= 20, "rows")
    stopped = client.call("record_stop")
    RecordStopReply.model_validate(stopped)
    assert stopped["ended"] == "stopped" and stopped["cycles_missing"] == 0 and stopped["rows_written"] >= 20
    with open(data_dir / "long.csv") as handle:
        header = handle.readline().strip()
        rows = handle.read().splitlines()
    assert header == "t_s,cycle,lateness_us,compute_us" and len(rows) == stopped["rows_written"]
    with pytest.raises(CommandError, match="nothing to stop") as nothing:
        client.call("record_stop")
    assert nothing.value.code == "not_recording"
    with pytest.raises(CommandError, match="long.csv exists.*choose another name") as exists:
        client.call("record", name="long", duration_s=1)
    assert exists.value.code == "file_exists"


def test_save_recording_never_takes_the_name_of_the_recording_under_way(client, data_dir) -> None:
    """Found from outside: save_recording wrote NAME.csv while recording NAME was under way,
    which then ended under its partial name without saying why, and a later record of
    NAME was refused as if a service had died during it."""
    def scenario() -> None:
        wait_for(lambda: at_rest(client), "rest")
        client.call("play", sequence="x_sweep")
        client.request("abort")  # any sequence's report will do: it has dwell records to save, or none
        client.call("record", name="taken", duration_s=600, signals=["lateness"])
        with pytest.raises(CommandError, match="taken.csv: the recording 'taken' under way writes it: choose another "
                                               "name") as refused:
            client.call("save_recording", path="taken.csv")
        assert refused.value.code == "file_exists"
        assert not (data_dir / "taken.csv").exists()
        stopped = client.call("record_stop")
        assert stopped["csv"] == str(data_dir / "taken.csv") and "write_error" not in stopped, stopped

    def cleanup() -> None:
        if client.call("record_status")["state"] == "writing":
            client.call("record_stop")
        for made in ("taken.csv", "taken.json", "taken.csv.partial"):
            (data_dir / made).unlink(missing_ok=True)

    tolerating_stalls(client, scenario, cleanup)

def test_a_recording_under_way_at_shutdown_ends_with_the_platform_at_rest(tmp_path) -> None:
    """Found from outside: the recording was finished when the API stopped taking commands,
    before the shutdown's brake, so a move under way was cut mid-motion and the brake and
    the rest pose were missing from the file."""
    with service_here(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    data_dirs=(tmp_path,))) as service, \
            HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
        client.call("enable")
        client.call("record", name="brake", duration_s=600, signals=["pose_command"])
        assert client.call("move", pose=[100, 0, 0, 0, 0, 0], duration=20)["ok"]
        wait_for(lambda: status(client)["pose_command"][0] > 1.0, "moving")
    side = json.loads((tmp_path / "brake.json").read_text())
    assert side["ended"] == "shutdown"
    with open(tmp_path / "brake.csv") as handle:
        x = [float(row["pose_command_x_mm"]) for row in csv.DictReader(handle)]
    # At rest, the commanded pose repeats (then, disabled, it follows the measured pose).
    assert any(x[i] == x[i + 1] for i in range(len(x) - 50, len(x) - 1)), "the file ends before the rest"
    assert 1.0 < x[-1] < 100.0
    assert len(set(x)) > 100, "no motion recorded before the brake"


def test_a_recording_under_way_is_finished_when_the_service_stops(tmp_path) -> None:
    with service_here(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    data_dirs=(tmp_path,))) as service, \
            HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
        client.call("record", name="cut", duration_s=600)
        wait_for(lambda: client.call("record_status").get("rows_written", 0) >= 50, "rows")
    side = json.loads((tmp_path / "cut.json").read_text())
    assert side["ended"] == "shutdown" and side["cycles_missing"] == 0 and side["rows_written"] >= 50
    with open(tmp_path / "cut.csv") as handle:
        assert sum(1 for _ in handle) == side["rows_written"] + 1  # the header, then every row written


def test_status_says_what_the_file_of_a_recording_done_says(tmp_path) -> None:
    """Found from outside: hexactl status said "done … (duration)" of a recording whose
    file failed, or that saw a fault, while record --wait and the side file said so."""
    from hexactl.adapters.cli.telemetry_text import recording_text

    done = {"state": "done", "name": "r7", "rows": 2000, "rows_requested": 2000, "lost": 0, "ended": "duration"}
    assert recording_text(done) == "r7 done 2000/2000 rows (duration)"
    failed = {**done, "file": {"ended": "write_failed", "faults_during": True}}
    assert recording_text(failed) == ("r7 done 2000/2000 rows (duration); its file: write_failed, rows missing (r7.json "
                                      "says why); FAULT or ESTOP during it (hexactl events says when)")
