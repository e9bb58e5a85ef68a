"""Every command round-trips through a real ROUTER to the (fake) controller, from REQ
and DEALER clients alike; controller refusals come back with their codes."""

from __future__ import annotations

from dataclasses import replace

import pytest
import zmq
from pydantic import TypeAdapter

from hexactl.control.snapshot import Event
from hexactl.adapters.api.commands import CommandHandler, MeasurementError, _dwells, _unsaved_dwells
from hexactl.adapters.api.messages import COMMANDS, REPLY_MODELS, ErrorReply, MeasureRequest, OkReply, PathViolation
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.sequence_player import SequenceReport
from tests.api.support import RECORDS, FakeController, request

REPLY = TypeAdapter(ErrorReply | OkReply)

ARGUMENTS: dict[str, dict] = {
    "move": {"pose": [0, 0, 50, 0, 0, 5], "duration": 2.0},
    "validate_pose": {"pose": [0, 0, 50, 0, 0, 5]},
    "leg_lock": {"leg": 3},
    "jog": {"velocity": [10, 0, 0, 0, 0, 0]},
    "play": {"sequence": "x_sweep"},
    "validate_sequence": {"sequence": "x_sweep"},
    "save_recording": {"path": "recording.csv"},
    "record": {"name": "run1", "duration_s": 1.0},
    "wave": {"axes": {"z": {"amplitude": 2.0}}, "frequency_hz": 1.0, "cycles": 3},
    "validate_wave": {"axes": {"z": {"amplitude": 2.0}}, "frequency_hz": 1.0, "cycles": 3},
    "progress": {"title": "postures", "done": 3, "total": 12, "label": "leg 1 locked", "said": "measuring"},
    "stream_open": {"source": "simulator", "timeout_ms": 50},
}


def send(service, cmd: str, kind: int = zmq.DEALER, request_id: object = 7, **fields) -> dict:
    reply = request(service.api, {"v": 1, "id": request_id, "cmd": cmd, **fields}, kind)
    model = REPLY_MODELS.get(cmd, OkReply) if reply["ok"] else ErrorReply
    model.model_validate(reply)  # what is sent is what the schema documents
    return reply


@pytest.mark.parametrize("kind", [zmq.REQ, zmq.DEALER], ids=["REQ", "DEALER"])
def test_every_command_round_trips(service, kind) -> None:
    fields = {
        **ARGUMENTS,
        "load_calibration": {"toml": geometry_to_toml(service.controller.geometry)},
        "validate_calibration": {"toml": geometry_to_toml(service.controller.geometry)},
        "read_file": {"path": ARGUMENTS["save_recording"]["path"]},  # written by save_recording, earlier in the list
    }
    for cmd in COMMANDS:
        service.controller.state = "enabled"  # whatever the previous command left
        reply = send(service, cmd, kind, request_id={"n": cmd}, **fields.get(cmd, {}))
        assert reply["ok"], reply
        assert reply["id"] == {"n": cmd}
    called = [name for name, _ in service.controller.calls]
    # queries and the instrument call nothing; clear_frames is a set_frames of no frames
    assert set(called) == set(COMMANDS) - {"status", "events", "validate_pose", "validate_wave", "validate_sequence",
                                           "save_recording",
                                           "measure", "frames", "clear_frames", "geometry", "files", "read_file",
                                           "progress"}


def test_events_reads_on_from_the_last_seen_and_counts_what_the_loop_dropped(service) -> None:
    service.controller.kept_events = tuple(Event(seq, seq * 1_000_000, "stop", f"stop {seq}", "ann (127.0.0.1)")
                                           for seq in range(11, 15))
    reply = send(service, "events", after=8)
    assert [event["seq"] for event in reply["events"]] == [11, 12, 13, 14] and reply["missed"] == 2
    assert reply["last"] == 14 and reply["events"][0] == {"seq": 11, "t": 0.011, "code": "stop", "message": "stop 11",
                                                          "sender": "ann (127.0.0.1)"}
    assert send(service, "events", after=14)["events"] == [] and send(service, "events")["missed"] == 10
    assert send(service, "events", after=-1)["error"]["code"] == "invalid_request"


def test_move_passes_pose_and_pace(service) -> None:
    service.controller.state = "enabled"
    send(service, "move", pose=[1, 2, 3, 4, 5, 6], duration=1.5)
    assert service.controller.calls[-1] == ("move", ([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 1.5, None))
    send(service, "move", pose=[1, 2, 3, 4, 5, 6], speed=0.5)
    assert service.controller.calls[-1] == ("move", ([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], None, 0.5))


def test_controller_refusal_keeps_its_code(service) -> None:
    reply = send(service, "move", pose=[0, 0, 10, 0, 0, 0])
    assert reply["error"]["code"] == "not_enabled"
    assert reply["id"] == 7


def test_a_loop_refusal_keeps_its_details_but_not_the_loop_ticket(service, monkeypatch) -> None:
    """The loop's verdicts carry the command's ticket, which numbers commands inside the
    service: a client sees the refusal and its details, not that number."""
    monkeypatch.setattr(service.controller, "stream_close", lambda: CommandResult.failure(
        ErrorCode.NO_STREAM, "no stream is open", ticket=1_000_042, stream=None))
    reply = send(service, "stream_close")
    assert reply["error"]["code"] == "no_stream" and reply["error"]["message"] == "no stream is open"
    assert reply["error"]["details"] == {"stream": None}


def test_path_violation_lists_violations(service) -> None:
    service.controller.state = "enabled"
    reply = send(service, "move", pose=[700, 0, 0, 0, 0, 0])
    assert reply["error"]["code"] == "path_violation"
    violations = [PathViolation.model_validate(item) for item in reply["error"]["details"]["violations"]]
    assert "pose_range" in {violation.kind for violation in violations}


def test_move_reply_has_the_planned_goal_and_duration(service) -> None:
    service.controller.state = "enabled"
    reply = send(service, "move", pose=[0, 0, 50, 0, 0, 0], duration=3.0)
    assert (reply["goal"], reply["duration"]) == ([0, 0, 50, 0, 0, 0], 3.0)


def test_duration_and_speed_together_are_refused(service) -> None:
    reply = send(service, "move", pose=[0] * 6, duration=3.0, speed=0.5)
    assert reply["error"]["code"] == "invalid_request" and "not both" in reply["error"]["message"]


def test_validate_pose_answers_what_move_would(service) -> None:
    valid = send(service, "validate_pose", pose=[0, 0, 50, 0, 0, 0])
    assert valid["valid"] and valid["goal"] == [0, 0, 50, 0, 0, 0] and valid["refusal"] is None
    invalid = send(service, "validate_pose", pose=[0, 0, 0, 0, 40, 0])
    assert not invalid["valid"] and invalid["refusal"]["code"] == "path_violation"
    assert {"pitch"} <= {violation.get("axis") for violation in invalid["refusal"]["details"]["violations"]}
    assert service.controller.calls == []


def test_status_and_validate_pose_carry_the_predicted_accuracy_and_move_its_tolerance(service) -> None:
    assert send(service, "status")["predicted_accuracy"] is None  # the nominal: no covariance
    service.controller.accuracy = {"position_mm": 0.05, "position_axes_mm": [0.03, 0.03, 0.02], "orientation_deg": 0.002,
                                   "tool_point_mm": [0.0, 0.0, 300.0]}
    assert send(service, "status")["predicted_accuracy"] == service.controller.accuracy
    assert send(service, "validate_pose", pose=[0, 0, 50, 0, 0, 0])["predicted_accuracy"] == service.controller.accuracy
    assert send(service, "move", pose=[0, 0, 50, 0, 0, 0], tolerance_mm=0)["error"]["code"] == "invalid_request"


def test_status_carries_the_telemetry_record(service) -> None:
    reply = send(service, "status")
    assert reply["status"]["state"] == "disabled"
    assert reply["status"]["calibration_id"] == geometry_id(service.controller.geometry)


def test_status_carries_the_identification_warnings_of_the_calibration_in_force(service, nominal) -> None:
    """Found in review: a calibration written "weakly determined" said so when loaded, then
    nowhere: hexactl status, what an operator looks at later, showed only its id."""
    from hexactl.adapters.cli.service_commands import format_ok_reply
    from hexactl.kinematics.geometry import CalibrationInfo

    assert send(service, "status")["calibration_warnings"] == []  # the nominal: a geometry file
    warned = ["weakly determined: … the worst combination is known to ±70.6 mm", "the base moved as a whole"]
    service.controller.geometry = nominal.model_copy(update={"calibration": CalibrationInfo(
        method="full", created="now", input_sha256="0" * 64, postures=8, residual_rms_mm=0.1,
        status="weakly determined", warnings=tuple(warned))})
    reply = send(service, "status")
    assert reply["calibration_warnings"] == warned
    assert format_ok_reply("status", reply).splitlines()[-2:] == [f"warning: when identified: {w}" for w in warned]


def test_play_inline_waypoints(service) -> None:
    sequence = {"name": "steps", "waypoints": [{"pose": [0, 0, 10, 0, 0, 0], "speed": 0.5}, {"pose": [0] * 6, "dwell": 2.0}]}
    reply = send(service, "play", sequence=sequence)
    assert (reply["name"], reply["waypoints"], reply["duration"]) == ("steps", 2, 12.5)
    played = service.controller.calls[-1][1][0]
    assert (played.waypoints[0].speed, played.waypoints[1].dwell) == (0.5, 2.0)


def test_play_built_in(service) -> None:
    reply = send(service, "play", sequence="y_rotation")
    assert (reply["name"], reply["waypoints"]) == ("y_rotation", 9)


def test_play_refuses_a_waypoint_with_duration_and_speed(service) -> None:
    sequence = {"name": "both", "waypoints": [{"pose": [0] * 6, "speed": 0.5, "duration": 2.0}]}
    reply = send(service, "play", sequence=sequence)
    assert reply["error"]["code"] == "invalid_request"
    assert "not both" in reply["error"]["message"]


def test_play_unknown_name(service) -> None:
    reply = send(service, "play", sequence="no_such_motion")
    assert reply["error"]["code"] == "unknown_sequence"
    assert "x_sweep" in reply["error"]["details"]["built_in"]


@pytest.mark.parametrize("name", ["/etc/passwd", "sequences", "sequences/"])
def test_a_path_that_is_no_sequence_file_is_said_to_be_one(service, name) -> None:
    """Found from outside: a directory or /etc/passwd was "not a built-in sequence"."""
    name = str(service.data_dir / name) if not name.startswith("/") else name
    refused = send(service, "play", sequence=name)["error"]
    assert refused["code"] == "unknown_sequence", refused
    assert refused["message"] == (f"{name!r}: a path, but a sequence file's name ends in .toml and a posture plan's "
                                  "in .csv (a directory or another file cannot be played)"), refused["message"]


def test_a_directory_is_refused_by_the_cli_before_anything_is_sent(tmp_path, capsys) -> None:
    from hexactl.adapters.cli.main import main

    assert main(["play", str(tmp_path), "--api", "ipc://" + str(tmp_path / "nobody"), "--timeout", "0.2"]) == 2
    assert f"{tmp_path}: a directory, not a sequence: name a .toml sequence file or a .csv plan in it" in \
        capsys.readouterr().err


def test_validate_sequence_says_valid_with_the_plan_or_the_refusal_and_plays_nothing(service) -> None:
    steps = {"name": "steps", "waypoints": [{"pose": [0, 0, 10, 0, 0, 0]}, {"pose": [0, 0, 5, 0, 0, 0], "dwell": 1.0}]}
    valid = send(service, "validate_sequence", sequence=steps)
    assert valid == {**valid, "valid": True, "name": "steps", "waypoints": 2, "duration": 12.5,
                     "goal": [0, 0, 5, 0, 0, 0], "lock_corrections_mm": None, "refusal": None}
    refused = send(service, "validate_sequence", sequence="y_rotation")  # the fake refuses more than 3 waypoints
    assert refused == {**refused, "valid": False, "name": "y_rotation", "waypoints": 9, "duration": None, "goal": None}
    assert refused["refusal"] == {"code": "path_violation", "message": "waypoint 4: leg 2 beyond its stroke",
                                  "details": {"waypoint": 4}}
    assert send(service, "validate_sequence", sequence="no_such_motion")["error"]["code"] == "unknown_sequence"
    assert [name for name, _ in service.controller.calls if name == "play"] == []


def test_a_sequence_files_name_without_its_ending_is_pointed_at_the_file(service) -> None:
    """Found from outside: play xy_square (its file xy_square.toml in ./sequences) was told
    only that xy_square is no built-in."""
    (service.data_dir / "xy_square.toml").write_text('name = "xy_square"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\n')
    refused = send(service, "play", sequence="xy_square")["error"]
    assert refused["code"] == "unknown_sequence" and refused["details"]["file"] == str(service.data_dir / "xy_square.toml")
    assert refused["message"].endswith(f"; but {service.data_dir / 'xy_square.toml'} is a sequence file there: play "
                                       "xy_square.toml (a file is named with its ending)"), refused["message"]
    assert "file" not in send(service, "play", sequence="no_such_motion")["error"]["details"]
    assert send(service, "play", sequence="xy_square.toml")["ok"]


def test_load_and_roll_back_calibration(service, nominal) -> None:
    calibrated = nominal.model_copy(update={"name": "calibrated", "zero_lengths": (1751.0,) * 6})
    loaded = send(service, "load_calibration", toml=geometry_to_toml(calibrated))
    assert loaded["calibration_id"] == geometry_id(calibrated) != geometry_id(nominal)
    assert service.controller.calls[-1][1][1:] == (geometry_id(calibrated), "request")
    rolled_back = send(service, "rollback_calibration")
    assert rolled_back["calibration_id"] == geometry_id(nominal)
    assert send(service, "rollback_calibration")["error"]["code"] == "no_previous_calibration"


def test_invalid_calibration_names_each_problem(service) -> None:
    reply = send(service, "load_calibration", toml="zero_lengths = [1, 2]\n")
    assert reply["error"]["code"] == "invalid_calibration"
    assert len(reply["error"]["details"]) > 1
    assert all(line.startswith("request: ") for line in reply["error"]["details"])
    assert send(service, "load_calibration", toml="= not toml")["error"]["code"] == "invalid_calibration"
    assert service.controller.calls == []


def test_load_calibration_needs_exactly_one_source(service) -> None:
    reply = send(service, "load_calibration", path="a.toml", toml="")
    assert reply["error"]["code"] == "invalid_request"
    assert send(service, "load_calibration")["error"]["code"] == "invalid_request"


def test_a_play_over_dwell_records_never_saved_says_it_replaces_them(service) -> None:
    """Found from outside: playing a sequence dropped the last one's dwell records, which
    only save_recording keeps, without a word."""
    assert send(service, "play", sequence="compound")["message"] == "playing compound"  # none before it
    assert send(service, "play", sequence="x_sweep")["message"] == (
        "playing x_sweep; the 2 dwell record(s) of compound, never saved, are replaced by this sequence's "
        "(save_recording saves a sequence's records before the next one plays)")
    send(service, "save_recording", path="sweep.csv")
    assert send(service, "play", sequence="y_rotation")["message"] == "playing y_rotation"  # saved: nothing lost


def test_a_save_made_while_the_sequence_played_leaves_only_its_later_dwell_records_unsaved() -> None:
    """Found by a reviewer: save_recording mid-sequence saved its first records; the next
    play called all of them "never saved"."""
    report = SequenceReport("x_sweep", "finished", RECORDS + (replace(RECORDS[1], waypoint=3, t_s=15.0),))
    partly = _dwells(SequenceReport("x_sweep", "playing", RECORDS))
    assert _unsaved_dwells(report, partly) == ("the 1 dwell record(s) of x_sweep after the 2 saved, never saved, are "
                                               "replaced by this sequence's (save_recording saves a sequence's "
                                               "records before the next one plays)")
    assert _unsaved_dwells(report, _dwells(report)) is None
    assert _unsaved_dwells(report, _dwells(replace(report, name="other"))).startswith("the 3 dwell record(s) of x_sweep,")
    assert _unsaved_dwells(replace(report, records=()), None) is None


def test_save_recording_writes_csv_once(service) -> None:
    assert send(service, "save_recording", path="run.csv")["error"]["code"] == "no_recording"
    send(service, "play", sequence="compound")
    reply = send(service, "save_recording", path="run.csv")
    assert (reply["records"], reply["status"]) == (2, "playing")
    lines = (service.data_dir / "run.csv").read_text().splitlines()
    assert lines[0].startswith("sequence,waypoint,t_s,command_x") and len(lines) == 3
    assert send(service, "save_recording", path="run.csv")["error"]["code"] == "file_exists"
    assert send(service, "save_recording", path="../run.csv")["error"]["code"] == "forbidden_path"
    assert send(service, "save_recording", path="missing/run.csv")["error"]["code"] == "file_not_found"
    for name in ("run2", "run2.json", "run2.csv.tmp"):  # CSV by its name too, or refused saying so
        refused = send(service, "save_recording", path=name)["error"]
        assert refused["code"] == "invalid_request" and refused["message"] == (
            f"{name}: a recording is CSV: name it with the ending .csv"), refused
    assert send(service, "save_recording", path="RUN2.CSV")["records"] == 2


def test_measure_returns_the_instruments_points(service, nominal) -> None:
    points = send(service, "measure")["points"]
    assert len(points) == len(nominal.measurement.feature_points)
    assert points[0] == pytest.approx([800.0, 0.0, 2000.0])


def test_measure_without_an_instrument_or_when_it_fails(nominal, tmp_path) -> None:
    def broken() -> list[list[float]]:
        raise MeasurementError("no pose")

    request = MeasureRequest(v=1, id=1, cmd="measure")
    for instrument, code in ((None, "no_instrument"), (broken, "measurement_failed")):
        handler = CommandHandler(FakeController(nominal), DataDirectories([tmp_path]), instrument)
        with pytest.raises(ApiError) as refused:
            handler(request)
        assert refused.value.code == code


def test_the_platform_outside_the_soft_limits_is_logged_once_as_it_happens(nominal, tmp_path, caplog) -> None:
    """Found from outside: a service restored soft limits the platform stood outside of, and
    its log said only that the frames were restored."""
    controller = FakeController(nominal, outside_soft_limits=("y 15.161 mm above the soft limit 10 mm",))
    handler = CommandHandler(controller, DataDirectories([tmp_path]))
    with caplog.at_level("WARNING", logger="hexactl.adapters.api.commands"):
        assert handler.record()["outside_soft_limits"] == ["y 15.161 mm above the soft limit 10 mm"]
        handler.record()
        controller.outside_soft_limits = ()
        handler.record()
        controller.outside_soft_limits = ("x 51 mm above the soft limit 50 mm",)
        handler.record()
    assert [r.getMessage() for r in caplog.records] == [
        "the platform is outside the operator's soft limits: y 15.161 mm above the soft limit 10 mm; moves may only "
        "go back inside",
        "the platform is outside the operator's soft limits: x 51 mm above the soft limit 50 mm; moves may only go back "
        "inside"]
