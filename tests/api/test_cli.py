"""The CLI clients against a service running in-process on a random port: exit status
0 on ok, 1 on an error reply, 2 when nobody answers; ``monitor --once``; ``keys``."""

from __future__ import annotations

import json

import pytest

from hexactl.adapters.api.messages import Telemetry
from hexactl.adapters.api.wire import jsonable
from hexactl.adapters.cli.main import main
from hexactl.adapters.cli.service_commands import format_telemetry
from hexactl.adapters.cli.telemetry_text import leg_state_text
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.control.hardware import fault_text


def run(service, command: str, *arguments: str) -> int:
    return main([command, "--api", service.api, *arguments])


@pytest.mark.parametrize(
    "arguments",
    [
        ["status"], ["enable"], ["disable"], ["stop"], ["estop"], ["reset"], ["pause"], ["resume"], ["abort"],
        ["leg-lock", "2"], ["unlock"], ["play", "x_sweep"],
    ],
)
def test_commands_exit_zero_when_ok(service, arguments, capsys) -> None:
    assert run(service, *arguments) == 0
    assert capsys.readouterr().out.strip()


def test_move_sends_the_parsed_pose(service, capsys) -> None:
    service.controller.state = "enabled"
    assert run(service, "move", "z=50,yaw=5", "--duration", "2") == 0
    assert service.controller.calls[-1] == ("move", ([0.0, 0.0, 50.0, 0.0, 0.0, 5.0], 2.0, None))
    assert run(service, "move", "--speed", "0.5", "--", "-10,0,0,0,0,0") == 0
    assert service.controller.calls[-1] == ("move", ([-10.0, 0.0, 0.0, 0.0, 0.0, 0.0], None, 0.5))
    assert capsys.readouterr().out.startswith("ok")


def test_refusal_exits_one_and_says_why(service, capsys) -> None:
    service.controller.state = "enabled"
    assert run(service, "move", "x=700") == 1
    err = capsys.readouterr().err
    assert err.startswith("error path_violation: x 700 mm outside the pose envelope")


def test_json_prints_the_raw_reply(service, capsys) -> None:
    assert run(service, "status", "--json") == 0
    reply = json.loads(capsys.readouterr().out)
    Telemetry.model_validate(reply["status"])


def test_no_answer_exits_two(tmp_path, capsys) -> None:
    endpoint = f"ipc://{tmp_path}/nobody"
    assert main(["status", "--api", endpoint, "--timeout", "0.2"]) == 2
    assert f"no answer from {endpoint}" in capsys.readouterr().err


def test_bad_arguments_exit_two(service) -> None:
    with pytest.raises(SystemExit) as exited:
        run(service, "move", "1,2,3")
    assert exited.value.code == 2
    with pytest.raises(SystemExit):
        run(service, "leg-lock", "7")


def test_load_calibration_by_path_or_content(service, nominal, tmp_path, capsys) -> None:
    calibrated = nominal.model_copy(update={"name": "sent"})
    inside = service.data_dir / "c.toml"
    inside.write_text(geometry_to_toml(calibrated))
    assert run(service, "load-calibration", str(inside)) == 0
    assert capsys.readouterr().out.startswith(f"ok: calibration {geometry_id(calibrated)} loaded")
    elsewhere = tmp_path / "elsewhere.toml"
    elsewhere.write_text(geometry_to_toml(calibrated))
    assert run(service, "load-calibration", str(elsewhere)) == 0  # a file here is read here and sent
    assert run(service, "load-calibration", "--send", str(elsewhere)) == 0
    assert run(service, "rollback-calibration") == 0


def test_load_calibration_previews_then_loads_only_what_was_previewed(service, nominal, tmp_path, capsys) -> None:
    """As the dashboard's Preview and Apply: --preview loads nothing and names the id;
    --expected-id loads the file only while it holds that calibration."""
    previewed = nominal.model_copy(update={"name": "previewed"})
    rewritten = nominal.model_copy(update={"name": "rewritten since"})
    file = tmp_path / "cal.toml"
    file.write_text(geometry_to_toml(previewed))
    assert run(service, "load-calibration", str(file), "--preview") == 0
    out = capsys.readouterr().out
    assert out.startswith(f"ok: calibration {geometry_id(previewed)} would change the set-points by at most 0.500 mm")
    assert f"nothing loaded: to load this very calibration, --expected-id {geometry_id(previewed)}" in out
    assert [call[0] for call in service.controller.calls] == ["validate_calibration"]

    file.write_text(geometry_to_toml(rewritten))
    assert run(service, "load-calibration", str(file), "--expected-id", geometry_id(previewed)) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error changed_since_validation: the text sent is calibration {geometry_id(rewritten)}, "
                          f"not calibration {geometry_id(previewed)} as previewed"), err
    assert service.controller.calibrations == []

    file.write_text(geometry_to_toml(previewed))
    assert run(service, "load-calibration", str(file), "--expected-id", geometry_id(previewed)) == 0
    assert service.controller.calibrations == [geometry_id(previewed)]


def test_load_calibration_preview_of_what_the_service_refuses_exits_one(service, capsys) -> None:
    assert run(service, "load-calibration", "no-such-calibration.toml", "--preview") == 1
    assert capsys.readouterr().err.startswith("error file_not_found:")
    assert service.controller.calls == []


def test_load_calibration_of_a_directory_here_says_so(service, tmp_path, capsys) -> None:
    """It was sent as a name, and the service answered that no such file exists."""
    assert run(service, "load-calibration", str(tmp_path)) == 2
    assert f"{tmp_path}: a directory, not a calibration file: name the .toml file in it" in capsys.readouterr().err
    assert service.controller.calls == []


def test_save_recording(service, capsys) -> None:
    assert run(service, "play", "compound") == 0
    target = service.data_dir / "run.csv"
    assert run(service, "save-recording", str(target)) == 0
    assert capsys.readouterr().out.strip().endswith(f"2 records of compound (playing) written to {target}")
    assert run(service, "save-recording", str(target)) == 1  # never overwrites


def test_monitor_once(service, capsys) -> None:
    assert main(["monitor", "--once", "--telemetry", service.telemetry]) == 0
    out = capsys.readouterr().out
    assert out.startswith("state          disabled, holding") and "calibration" in out
    assert main(["monitor", "--once", "--json", "--telemetry", service.telemetry]) == 0
    Telemetry.model_validate_json(capsys.readouterr().out)


def test_telemetry_text_with_unknown_values(service) -> None:
    record = jsonable(service.controller.telemetry())
    record.update(pose_measured=None, leg_feedback=[None, 1.0, 2.0, 3.0, 4.0, 5.0], locked_leg=2,
                  sequence={"name": "s", "index": 2, "total": 3, "phase": "dwelling"},
                  faults=[{"code": "heartbeat_lost", "message": "no report", "leg": 4}])
    text = format_telemetry(record)
    assert "pose measured  unknown" in text and "L1        ?  L2    1.000" in text
    assert "sequence       s 2/3 (dwelling)" in text and "leg 4: heartbeat_lost (no report)" in text


def test_telemetry_text_names_each_legs_state_fault_bits_and_silence(service) -> None:
    record = jsonable(service.controller.telemetry())
    healthy = {"state": "disabled", "fault_bits": 0, "fault_names": [], "report_age_s": 0.002}
    assert "legs           unknown\n" in format_telemetry({**record, "legs": None})
    assert "legs           all disabled\n" in format_telemetry({**record, "legs": [healthy] * 6})
    faulted = {"state": "fault", "fault_bits": 0x2081, "fault_names": ["comm_timeout", "sensor", "bit_13"],
               "report_age_s": 0.01}
    record["legs"] = [healthy] * 4 + [faulted, {**healthy, "report_age_s": 6.3}]
    line = next(line for line in format_telemetry(record).splitlines() if line.startswith("legs "))
    assert line.endswith("L4 disabled  L5 fault: comm_timeout, sensor, bit_13 (0x2081)  L6 disabled; "
                         "no report lately: L6 6.3 s"), line
    # The same form as the service's messages (the CLI does not import it: status loads no control module).
    assert leg_state_text(faulted) == "fault: " + fault_text(faulted["fault_names"], faulted["fault_bits"])


def test_monitor_without_service_exits_two(tmp_path, capsys) -> None:
    assert main(["monitor", "--once", "--telemetry", f"ipc://{tmp_path}/nobody", "--timeout", "0.2"]) == 2
    assert "no telemetry" in capsys.readouterr().err


def test_bad_client_keys_exit_two(service, tmp_path, capsys) -> None:
    (tmp_path / "junk.key").write_text("not a certificate")
    assert run(service, "status", "--curve-server", str(tmp_path / "missing.key"), "--curve-client", str(tmp_path / "junk.key")) == 2
    assert "CURVE keys" in capsys.readouterr().err
    assert run(service, "status", "--curve-server", str(tmp_path / "junk.key")) == 2  # one without the other


def test_keys(tmp_path, capsys) -> None:
    assert main(["keys", "--out", str(tmp_path / "k")]) == 0
    assert "--curve-secret" in capsys.readouterr().out
    assert main(["keys", "--out", str(tmp_path / "k")]) == 2  # refuses to overwrite


def test_telemetry_text_says_how_the_last_stream_ended_and_a_stopped_stream_input(service) -> None:
    record = jsonable(service.controller.telemetry())
    assert "\nstream         none\n" in format_telemetry(record)
    ended = {**record, "last_stream": {"stream": 7, "reason": "timeout: no target for 54 ms", "targets": 1200}}
    assert "\nstream         none (stream 7 ended: timeout: no target for 54 ms, 1200 targets)\n" in format_telemetry(ended)
    stopped = {"running": False, "stream": None, "received": 0}
    assert "\nSTREAM INPUT   stopped: stream_open is refused until the service restarts" in \
        format_telemetry({**record, "stream_input": stopped})
