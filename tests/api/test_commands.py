"""Every command round-trips through a real ROUTER to the (fake) controller, from REQ
and DEALER clients alike; controller refusals come back with their codes."""

from __future__ import annotations

import pytest
import zmq
from pydantic import TypeAdapter

from hexactl.adapters.api.messages import COMMANDS, REPLY_MODELS, ErrorReply, OkReply
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from tests.api.support import request

REPLY = TypeAdapter(ErrorReply | OkReply)

ARGUMENTS: dict[str, dict] = {
    "move": {"pose": [0, 0, 50, 0, 0, 5], "duration": 2.0},
    "validate_pose": {"pose": [0, 0, 50, 0, 0, 5]},
    "leg_lock": {"leg": 3},
    "play": {"sequence": "x_sweep"},
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
    }
    for cmd in COMMANDS:
        service.controller.state = "enabled"  # whatever the previous command left
        reply = send(service, cmd, kind, request_id={"n": cmd}, **fields.get(cmd, {}))
        assert reply["ok"], reply
        assert reply["id"] == {"n": cmd}
    called = [name for name, _ in service.controller.calls]
    assert set(called) == set(COMMANDS) - {"status", "validate_pose"}


def test_move_passes_pose_duration_and_speed(service) -> None:
    service.controller.state = "enabled"
    send(service, "move", pose=[1, 2, 3, 4, 5, 6], duration=1.5, speed=0.5)
    assert service.controller.calls[-1] == ("move", ([1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 1.5, 0.5))


def test_controller_refusal_keeps_its_code(service) -> None:
    reply = send(service, "move", pose=[0, 0, 10, 0, 0, 0])
    assert reply["error"]["code"] == "not_enabled"
    assert reply["id"] == 7


def test_out_of_workspace_lists_violations(service) -> None:
    service.controller.state = "enabled"
    reply = send(service, "move", pose=[700, 0, 0, 0, 0, 0])
    assert reply["error"]["code"] == "out_of_workspace"
    kinds = {violation["kind"] for violation in reply["error"]["details"]}
    assert "pose_range" in kinds
    assert all(isinstance(violation["message"], str) for violation in reply["error"]["details"])


def test_validate_pose_reports_without_moving(service) -> None:
    reachable = send(service, "validate_pose", pose=[0, 0, 50, 0, 0, 0])
    assert reachable["reachable"] and reachable["violations"] == []
    assert len(reachable["leg_setpoints"]) == 6
    unreachable = send(service, "validate_pose", pose=[0, 0, 0, 0, 40, 0])
    assert not unreachable["reachable"]
    assert {"pitch"} <= {violation.get("axis") for violation in unreachable["violations"]}
    assert service.controller.calls == []


def test_status_carries_the_telemetry_record(service) -> None:
    reply = send(service, "status")
    assert reply["status"]["state"] == "disabled"
    assert reply["status"]["calibration_id"] == geometry_id(service.controller.geometry)


def test_play_inline_waypoints(service) -> None:
    sequence = {"name": "steps", "waypoints": [{"pose": [0, 0, 10, 0, 0, 0], "speed": 0.5}, {"pose": [0] * 6, "dwell": 2.0}]}
    reply = send(service, "play", sequence=sequence)
    assert reply["sequence"] == {"name": "steps", "index": 0, "total": 2}
    played = service.controller.calls[-1][1][0]
    assert (played.waypoints[0].speed, played.waypoints[1].dwell) == (0.5, 2.0)


def test_play_refuses_a_waypoint_with_duration_and_speed(service) -> None:
    sequence = {"name": "both", "waypoints": [{"pose": [0] * 6, "speed": 0.5, "duration": 2.0}]}
    reply = send(service, "play", sequence=sequence)
    assert reply["error"]["code"] == "invalid_sequence"
    assert "not both" in reply["error"]["message"]


def test_play_unknown_name(service) -> None:
    reply = send(service, "play", sequence="no_such_motion")
    assert reply["error"]["code"] == "unknown_sequence"
    assert "x_sweep" in reply["error"]["details"]["built_in"]


def test_load_and_roll_back_calibration(service, nominal) -> None:
    calibrated = nominal.model_copy(update={"name": "calibrated", "zero_lengths": (1751.0,) * 6})
    loaded = send(service, "load_calibration", toml=geometry_to_toml(calibrated))
    assert loaded["calibration_id"] == geometry_id(calibrated) != geometry_id(nominal)
    assert loaded["name"] == "calibrated"
    rolled_back = send(service, "rollback_calibration")
    assert rolled_back["calibration_id"] == geometry_id(nominal)
    assert send(service, "rollback_calibration")["error"]["code"] == "no_previous_calibration"


def test_invalid_calibration_names_each_problem(service) -> None:
    reply = send(service, "load_calibration", toml="zero_lengths = [1, 2]\n")
    assert reply["error"]["code"] == "invalid_calibration"
    assert len(reply["error"]["details"]) > 1
    assert all(line.startswith("toml: ") for line in reply["error"]["details"])
    assert send(service, "load_calibration", toml="= not toml")["error"]["code"] == "invalid_calibration"
    assert service.controller.calls == []


def test_load_calibration_needs_exactly_one_source(service) -> None:
    reply = send(service, "load_calibration", path="a.toml", toml="")
    assert reply["error"]["code"] == "invalid_request"
    assert send(service, "load_calibration")["error"]["code"] == "invalid_request"
