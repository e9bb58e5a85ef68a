"""A move sent with what ``validate_pose`` validated it under is refused once another
client has changed the frames, the soft limits or the calibration (found from outside: two
operators on one platform; a move validated in the work frame went, after the other
operator moved the work frame, to where the new frame put it, since the service checked
it again only in the new frames). Through the whole service on its simulator: the
platform does not move."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.application.service import Service, ServiceConfig
from hexactl.kinematics.geometry import Geometry
from tests.api.support import service_here
from tests.api.test_commands import send
from tests.api.test_service import WAIT_S, at_rest, status, wait_for
from tests.reliability.support import recover, tolerating_loop_stalls

TOOL_300 = [0, 0, 300, 0, 0, 0]
WORK_GOAL = [0, 0, 0, 4, 0, 0]  # a 4° roll about the pivot, 300 mm above the platform


@pytest.fixture(scope="module")
def framed_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    directory = tmp_path_factory.mktemp("validated")
    with service_here(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    data_dirs=(directory,), frames_path=directory / "frames.toml")) as service:
        yield service


@pytest.fixture
def operators(framed_service: Service) -> Iterator[tuple[HexactlClient, HexactlClient]]:
    """Two clients of the service (two operators), the platform enabled and at rest at the
    zero posture, the tool and work frames on a pivot 300 mm above the platform."""
    with HexactlClient(framed_service.api_endpoint, timeout_s=WAIT_S) as first, \
            HexactlClient(framed_service.api_endpoint, timeout_s=WAIT_S) as second:
        yield first, second


def at_zero_in_frames(client: HexactlClient) -> dict:
    """Enabled, at rest at the zero posture, the frames on the pivot; the status record."""
    recover(client)
    if status(client)["pose_command"] != pytest.approx([0] * 6, abs=1e-9):
        client.call("move", pose=[0] * 6, duration=0.5)
        wait_for(lambda: at_rest(client), "back at the zero posture")
    client.call("set_frames", tool=TOOL_300, work=TOOL_300, soft_limits={})
    return status(client)


def test_a_move_validated_before_another_client_moved_the_work_frame_is_refused_and_nothing_moves(
        framed_service, operators) -> None:
    first, second = operators

    def scenario() -> None:
        at_zero_in_frames(first)
        validation = first.call("validate_pose", pose=WORK_GOAL, frame="work", duration=0.5)
        assert validation["valid"], validation
        under = validation["validated_under"]
        assert under["frames"]["work"] == TOOL_300 and under["calibration_id"] == status(first)["calibration_id"]

        second.call("set_frames", work=[30, 0, 300, 0, 0, 0])  # the other operator
        before = status(first)
        refused = first.request("move", pose=WORK_GOAL, frame="work", duration=0.5, validated_under=under)
        error = refused["error"]
        assert error["code"] == "changed_since_validation", refused
        assert error["details"]["changed"] == ["work frame"], error
        assert "the work frame changed since this move was validated" in error["message"], error
        assert "validate it again" in error["message"], error
        assert error["details"]["in_force"]["frames"]["work"] == [30, 0, 300, 0, 0, 0], error
        # nothing was sent to the loop: at rest where it was (a move would be under way from its reply on)
        after = status(first)
        assert after["motion"] == "holding" and after["goal"] is None, after
        assert after["pose_command"] == before["pose_command"], (before, after)

        # validate_pose answers as move would
        again = first.call("validate_pose", pose=WORK_GOAL, frame="work", duration=0.5, validated_under=under)
        assert not again["valid"] and again["refusal"]["code"] == "changed_since_validation", again

        # validated anew, under the new frame, it goes, to the goal this validation gave
        fresh = first.call("validate_pose", pose=WORK_GOAL, frame="work", duration=0.5)
        moved = first.call("move", pose=WORK_GOAL, frame="work", duration=0.5, validated_under=fresh["validated_under"])
        assert moved["goal"] == pytest.approx(fresh["goal"], abs=1e-9)
        assert fresh["goal"][0] == pytest.approx(validation["goal"][0] + 30, abs=1e-6)  # where the old one would have gone
        wait_for(lambda: at_rest(first), "the move's end")

    tolerating_loop_stalls(scenario, lambda: framed_service.controller)


def test_a_move_validated_before_another_client_loaded_a_calibration_is_refused_until_it_is_rolled_back(
        framed_service, operators, nominal: Geometry, tmp_path: Path) -> None:
    first, second = operators
    calibrated = nominal.model_copy(update={"name": "other operator's", "zero_lengths": tuple(
        length + 0.3 for length in nominal.zero_lengths)})

    def scenario() -> None:
        at_zero_in_frames(first)
        under = first.call("validate_pose", pose=WORK_GOAL, frame="work", duration=0.5)["validated_under"]
        second.call("load_calibration", toml=geometry_to_toml(calibrated))
        wait_for(lambda: status(first)["calibration_id"] == geometry_id(calibrated), "the calibration swapped in")
        wait_for(lambda: at_rest(first), "the calibration's ramp at its end")
        refused = first.request("move", pose=WORK_GOAL, frame="work", duration=0.5, validated_under=under)
        assert refused["error"]["code"] == "changed_since_validation", refused
        assert refused["error"]["details"]["changed"] == ["calibration"], refused
        assert "the calibration changed since this move was validated" in refused["error"]["message"], refused
        assert status(first)["motion"] == "holding"

        # what it was validated under is in force again: the validation holds again
        second.call("rollback_calibration")
        wait_for(lambda: status(first)["calibration_id"] == under["calibration_id"], "rolled back")
        wait_for(lambda: at_rest(first), "the rollback's ramp at its end")
        first.call("move", pose=WORK_GOAL, frame="work", duration=0.5, validated_under=under)
        wait_for(lambda: at_rest(first), "the move's end")

    tolerating_loop_stalls(scenario, lambda: framed_service.controller)


def test_a_relative_move_validated_before_another_client_moved_the_platform_is_refused_and_nothing_moves(
        framed_service, operators) -> None:
    """A relative move starts from the target, so after another client's move the same
    request goes elsewhere than the goal validated; the service passed it on (only the
    frames and the calibration were checked; the dashboard alone withdrew Go). Its goal is
    checked now."""
    first, second = operators

    def scenario() -> None:
        start = at_zero_in_frames(first)["pose_command"]
        validation = first.call("validate_pose", pose=[10, 0, 0, 0, 0, 0], relative=True, duration=0.5)
        under = validation["validated_under"]
        assert under["goal"] == pytest.approx(validation["goal"], abs=1e-12)
        assert validation["goal"][0] == pytest.approx(start[0] + 10, abs=1e-6)

        second.call("move", pose=[25, 0, 0, 0, 0, 0], relative=True, duration=0.5)  # the other operator
        wait_for(lambda: at_rest(first), "the other operator's move at its end")
        before = status(first)
        refused = first.request("move", pose=[10, 0, 0, 0, 0, 0], relative=True, duration=0.5, validated_under=under)
        error = refused["error"]
        assert error["code"] == "changed_since_validation", refused
        assert error["details"]["changed"] == ["goal"], error
        assert error["details"]["validated_goal"] == pytest.approx(validation["goal"], abs=1e-12), error
        assert error["details"]["goal"][0] == pytest.approx(start[0] + 35, abs=1e-6), error
        assert "the goal changed since this move was validated (x 10 → 35 mm)" in error["message"], error
        after = status(first)
        assert after["motion"] == "holding" and after["goal"] is None, after
        assert after["pose_command"] == before["pose_command"], (before, after)
        again = first.call("validate_pose", pose=[10, 0, 0, 0, 0, 0], relative=True, duration=0.5,
                           validated_under=under)
        assert not again["valid"] and again["refusal"]["details"]["changed"] == ["goal"], again

        # from where it was validated, the same validation holds again
        second.call("move", pose=[-25, 0, 0, 0, 0, 0], relative=True, duration=0.5)
        wait_for(lambda: at_rest(first), "the other operator's move back")
        moved = first.call("move", pose=[10, 0, 0, 0, 0, 0], relative=True, duration=0.5, validated_under=under)
        assert moved["goal"] == pytest.approx(validation["goal"], abs=1e-6)
        wait_for(lambda: at_rest(first), "the move's end")

    tolerating_loop_stalls(scenario, lambda: framed_service.controller)


def test_an_absolute_move_validated_before_a_leg_was_locked_is_refused_naming_the_lock(framed_service,
                                                                                      operators) -> None:
    """Found from outside (the dashboard's Go): the refusal blamed "a relative move … the
    platform has moved" for an absolute move whose goal the new lock projected elsewhere."""
    first, second = operators

    def scenario() -> None:
        at_zero_in_frames(first)
        validation = first.call("validate_pose", pose=[0, 0, 20, 0, 0, 0], duration=0.5)
        second.call("leg_lock", leg=2)
        try:
            refused = first.request("move", pose=[0, 0, 20, 0, 0, 0], duration=0.5,
                                    validated_under=validation["validated_under"])
        finally:
            second.call("leg_unlock")
        error = refused["error"]
        assert error["code"] == "changed_since_validation" and error["details"]["changed"] == ["goal"], refused
        assert "leg 2 is locked, and the goal is projected onto its constraint" in error["message"], error
        assert "relative" not in error["message"], error

    tolerating_loop_stalls(scenario, lambda: framed_service.controller)


def test_an_absolute_move_validated_before_an_estop_goes_to_the_goal_validated_once_enabled_again(
        framed_service, operators) -> None:
    """Its goal depends on nothing that an E-stop changes, and its path is planned anew from
    where the platform is: the validation holds across the E-stop and the re-enable."""
    first, _ = operators

    def scenario() -> None:
        at_zero_in_frames(first)
        validation = first.call("validate_pose", pose=[0, 0, 0, 2, 0, 0], frame="work", duration=0.5)
        first.call("estop")
        recover(first)
        moved = first.call("move", pose=[0, 0, 0, 2, 0, 0], frame="work", duration=0.5,
                           validated_under=validation["validated_under"])
        assert moved["goal"] == pytest.approx(validation["goal"], abs=1e-6)
        wait_for(lambda: at_rest(first), "the move's end")

    tolerating_loop_stalls(scenario, lambda: framed_service.controller)


@pytest.mark.parametrize("validated_under, fragment", [
    ({"calibration_id": 7, "frames": {}}, "calibration_id"),
    ({"calibration_id": "abc"}, "frames"),
    ({"calibration_id": "abc", "frames": {"work": ["0", 0, 0, 0, 0, 0]}}, "work"),
    ({"calibration_id": "abc", "frames": {}, "goal": [0] * 6, "epoch": 3}, "epoch"),
    ({"calibration_id": "abc", "frames": {}}, "goal"),
    ({"calibration_id": "abc", "frames": {}, "goal": [0, 0, 0, 0, 0]}, "goal"),
])
def test_a_malformed_validated_under_is_an_invalid_request(service, validated_under, fragment) -> None:
    reply = send(service, "move", pose=[0] * 6, validated_under=validated_under)
    assert reply["error"]["code"] == "invalid_request" and fragment in reply["error"]["message"], reply
    assert service.controller.calls == []
