"""``play`` of a posture plan CSV (what ``hexactl plan-leglock`` writes) and of a name that
is not a built-in sequence: through the API (a fake controller behind the real server),
and the resulting sequence validated whole by the real controller on the nominal
geometry."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.measurements import format_plan
from hexactl.adapters.files.sequence_file import sequence_from_plan
from hexactl.calibration.planning import PlanStatus, PosturePlan
from hexactl.control.sequences import BUILTIN_DWELL_S, BUILTIN_SEQUENCES
from tests.api.test_commands import send
from tests.control.conftest import Rig

POSTURES = 4


@pytest.fixture(scope="module")
def plan_text(tmp_path_factory) -> str:
    """A leg-3 plan as ``hexactl plan-leglock`` writes it (comments and all)."""
    path = tmp_path_factory.mktemp("plan") / "leg3.csv"
    assert main(["plan-leglock", "--leg", "3", "--count", str(POSTURES), "--seed", "1", "-o", str(path)]) == 0
    return path.read_text()


def plan_rows(text: str) -> list[list[float]]:
    rows = [line.split(",") for line in text.splitlines() if line and not line.startswith("#")][1:]
    return [[float(value) for value in row[1:7]] for row in rows]


def test_a_plan_from_plan_leglock_plays_its_poses_in_order(service, plan_text) -> None:
    (service.data_dir / "leg3.csv").write_text(plan_text)
    reply = send(service, "play", sequence="leg3.csv")
    assert reply["ok"] and (reply["name"], reply["waypoints"]) == ("leg3", POSTURES), reply
    played = service.controller.calls[-1][1][0]
    assert [list(w.pose) for w in played.waypoints] == plan_rows(plan_text)
    assert {(w.dwell, w.duration, w.speed) for w in played.waypoints} == {(BUILTIN_DWELL_S, None, None)}
    assert "leg 3 locked" in played.description


def test_a_plan_validates_whole_on_the_real_controller(nominal, plan_text) -> None:
    """Every posture's path planned before anything moves: the plan as it is passes, the
    same plan with one posture out of the envelope is refused naming that waypoint."""
    controller = Rig(nominal).controller
    valid = controller.validate_sequence(sequence_from_plan(plan_text, "leg3.csv"))
    assert valid.ok and valid.details["waypoints"] == POSTURES, valid.message
    lines = plan_text.splitlines()
    last = lines[-1].split(",")
    last[1] = "700"  # x beyond the envelope's 610 mm
    refused = controller.validate_sequence(sequence_from_plan("\n".join([*lines[:-1], ",".join(last)]), "leg3.csv"))
    assert not refused.ok and refused.message.startswith(f"waypoint {POSTURES}: "), refused.message


def test_a_leg_lock_plan_keeps_the_lock_of_its_leg_and_no_other(nominal, plan_text) -> None:
    """With the plan's leg locked where the plan locks it (its length in the zero
    posture), each posture lies on the lock: the plan validates and ends at its last
    posture. With another leg locked, the postures are far off that lock: refused."""
    sequence = sequence_from_plan(plan_text, "leg3.csv")
    locked = Rig(nominal).enabled()
    assert locked.controller.leg_lock(3).ok
    locked.run(5)
    valid = locked.controller.validate_sequence(sequence)
    assert valid.ok, valid.message
    np.testing.assert_allclose(valid.details["goal"], sequence.waypoints[-1].pose, atol=1e-6)
    other = Rig(nominal).enabled()
    assert other.controller.leg_lock(2).ok
    other.run(5)
    refused = other.controller.validate_sequence(sequence)
    assert not refused.ok and "leg 2 at its locked length" in refused.message, refused.message


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda lines: [*lines, "3,1,2,3"], r"leg3\.csv: line {end}: has 4 fields, the header has 13"),
    (lambda lines: [*lines[:-1], lines[-1].replace(",", ",abc", 1)], r"leg3\.csv: line {last}: .*'abc\S*' is not a number"),
    (lambda lines: [*lines[:-1], "9" + lines[-1][1:]], r"leg3\.csv: line {last}: leg '9' must be 0 \(none locked\) or a leg 1-6"),
    (lambda lines: [line.replace("_setpoint", "") if line.startswith("leg") else line for line in lines],
     r"leg3\.csv: line {header}: not a posture plan: missing columns l1_setpoint, .*hexactl plan-leglock"),
    (lambda lines: [line for line in lines if line.startswith(("#", "leg"))], r"leg3\.csv: a header but no postures"),
    # Found from outside: a pose beyond any platform's reach (a value in µm) was an internal_error.
    (lambda lines: [*lines[:-1], ",".join([*lines[-1].split(",")[:3], "1e7", *lines[-1].split(",")[4:]])],
     r"leg3\.csv: line {last}: z 1e7 is beyond ±1,000,000 mm, far beyond any platform or instrument: a typing or "
     r"unit error"),
])
def test_a_broken_plan_is_refused_naming_the_file_and_line(service, plan_text, edit, expected) -> None:
    lines = plan_text.splitlines()
    header = next(number for number, line in enumerate(lines, start=1) if line.startswith("leg"))
    (service.data_dir / "leg3.csv").write_text("\n".join(edit(lines)) + "\n")
    reply = send(service, "play", sequence="leg3.csv")
    assert reply["error"]["code"] == "invalid_sequence", reply
    pattern = expected.format(end=len(lines) + 1, last=len(lines), header=header)
    assert any(re.search(pattern, line) for line in reply["error"]["details"]), reply
    assert not any(name == "play" for name, _ in service.controller.calls)  # nothing played


def test_a_measurement_file_is_not_played_as_a_plan(service, tmp_path) -> None:
    """A measurement file's poses are absolute: played as relative ones they would be far off."""
    out = tmp_path / "data" / "measured.csv"
    assert main(["simulate-campaign", "--per-leg", "1", "--pose-form", "-o", str(out)]) == 0
    reply = send(service, "play", sequence="measured.csv")
    assert reply["error"]["code"] == "invalid_sequence"
    assert "measured.csv: line 3: not a posture plan: missing columns l1_setpoint" in reply["error"]["message"], reply


def test_a_mistyped_built_in_name_gets_the_list_and_a_guess(service) -> None:
    reply = send(service, "play", sequence="x_swep")
    error = reply["error"]
    assert error["code"] == "unknown_sequence" and error["details"]["built_in"] == list(BUILTIN_SEQUENCES)
    assert error["message"] == ("'x_swep' is not a built-in sequence (did you mean 'x_sweep'? built in: x_sweep, "
                                "y_rotation, compound); or name a .toml sequence file or a .csv plan (from hexactl "
                                "plan-leglock) in a data directory")
    assert "did you mean 'x_sweep'?" in send(service, "play", sequence="X_SWEEP")["error"]["message"]
    far = send(service, "play", sequence="circle")["error"]["message"]
    assert "did you mean" not in far and "built in: x_sweep, y_rotation, compound" in far


def test_a_file_suffix_is_read_whatever_its_case(service, plan_text) -> None:
    (service.data_dir / "LEG3.CSV").write_text(plan_text)
    assert send(service, "play", sequence="LEG3.CSV")["waypoints"] == POSTURES


poses = st.lists(st.lists(st.floats(-1000, 1000, allow_nan=False), min_size=6, max_size=6), min_size=1, max_size=20)


@settings(max_examples=50, deadline=None)
@given(poses=poses, leg=st.integers(0, 6))
def test_every_written_plan_reads_back_as_its_poses(poses, leg) -> None:
    values = np.array(poses)
    plan = PosturePlan(PlanStatus.OK, leg, values, np.zeros_like(values), float("nan"), float("nan"), len(poses), "")
    sequence = sequence_from_plan(format_plan(plan, ["a comment"]), "/data/p.csv")
    assert sequence.name == "p"
    np.testing.assert_allclose([w.pose for w in sequence.waypoints], values, rtol=0, atol=1e-9)


def test_the_cli_sends_a_plan_in_the_working_directory(service, plan_text, tmp_path, monkeypatch, capsys) -> None:
    """``hexactl play plan.csv`` from where the file is: the CLI sends it by its absolute
    path, which must lie in a data directory."""
    (service.data_dir / "leg3.csv").write_text(plan_text)
    monkeypatch.chdir(service.data_dir)
    assert main(["play", "leg3.csv", "--api", service.api]) == 0
    assert service.controller.calls[-1][1][0].name == "leg3"
    assert main(["play", "x_swep", "--api", service.api]) != 0
    assert "did you mean 'x_sweep'?" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["/.toml", ".toml", "PLAN.CSV", "sub/.csv"])
def test_a_name_ending_in_a_file_ending_is_looked_up_as_a_file(service, name) -> None:
    """Found by the fuzz: ``/.toml`` has no suffix to PurePath (a dot file), and was taken
    for a built-in's name."""
    assert send(service, "play", sequence=name)["error"]["code"] in ("file_not_found", "forbidden_path")
