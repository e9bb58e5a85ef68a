from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.config_path import CONFIG_ENVIRONMENT_VARIABLE


def test_check_shows_every_paper_extreme_reachable(capsys) -> None:
    assert main(["check"]) == 0
    out = capsys.readouterr().out
    assert "12 of 12 poses reachable" in out
    assert out.count("reachable") == 13 and "UNREACHABLE" not in out


def test_check_refuses_unreachable_poses_with_reasons(capsys) -> None:
    assert main(["check", "x=700", "pitch=-30,yaw=5", "--", "-600,0,0,0,0,0"]) == 1
    out = capsys.readouterr().out
    assert "x 700 mm outside the pose envelope" in out
    assert "pitch -30 deg outside the pose envelope" in out
    assert "1 of 3 poses reachable; 2 unreachable" in out


def test_check_of_a_hair_beyond_a_bound_reads_beyond_it(capsys) -> None:
    """Found from outside: "610,0,0,0,0,0 … x -0.0 mm" and "x 610 mm outside the pose envelope
    [-610, 610] mm (by 0.0001 mm)" for x 610.0001."""
    assert main(["check", "x=610.0001"]) == 1
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if "UNREACHABLE" in line)
    assert row.startswith("610.0001,0,0,0,0,0 ") and row.endswith("x -0.0001 mm"), row
    assert "x 610.0001 mm outside the pose envelope [-610, 610] mm (by 0.0001 mm)" in out


def test_check_json_has_margins(capsys) -> None:
    assert main(["check", "--json", "z=250"]) == 0
    (record,) = json.loads(capsys.readouterr().out)
    assert record["reachable"] and record["pose"] == [0, 0, 250, 0, 0, 0]
    assert min(record["stroke_margin_mm"]) > 0 and record["violations"] == []


def test_ik_then_fk_returns_the_pose(capsys) -> None:
    pose = [100.0, 100.0, 100.0, 5.0, 5.0, 5.0]
    assert main(["ik", *map(str, pose), "--json"]) == 0
    ik = json.loads(capsys.readouterr().out)
    assert ik["reachable"] and len(ik["setpoints_mm"]) == 6
    assert main(["fk", *map(repr, ik["setpoints_mm"]), "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    assert fk["status"] == "ok"
    np.testing.assert_allclose(fk["pose"], pose, atol=1e-7)


def test_fk_reports_non_convergence(capsys) -> None:
    assert main(["fk", "0", "850", "0", "850", "0", "850", "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["pose"] is None


def test_fk_json_of_a_diverged_solve_is_standard_json(capsys) -> None:
    """A reading far outside the stroke diverges with an infinite residual: printed as
    ``Infinity``, which is no JSON (jq and most parsers refuse the whole reply)."""
    assert main(["fk", "5000", "400", "400", "400", "400", "400", "--json"]) == 1
    reply = json.loads(capsys.readouterr().out, parse_constant=lambda name: pytest.fail(f"{name} is not JSON"))
    assert reply["status"] == "diverged" and reply["residual_mm"] is None


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["ik", "1", "2", "3", "nan", "0", "0"], "roll: 'nan' is not a finite number"),
        (["ik", "1", "2", "three", "0", "0", "0"], "z: 'three' is not a number"),
        # as check and move: 1e308 overflowed to leg lengths of inf, printed as JSON's non-standard Infinity
        (["ik", "1e308", "0", "0", "0", "0", "0", "--json"], "pose x 1e+308 is beyond any platform's reach"),
        (["fk", "1", "2", "3", "4", "5", "inf"], "L6: 'inf' is not a finite number"),
        (["sim-actuators", "--can", "socketcan:vcan0", "--positions", "1,2"], "give 6 numbers (L1,L2,L3,L4,L5,L6), not 2"),
        (["check", "--config", "/nonexistent/platform.toml"], "/nonexistent/platform.toml: no such file: check the name"),
    ],
)
def test_bad_arguments_get_a_named_error_and_status_2(argv, message, capsys) -> None:
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_bad_pose_argument_is_a_usage_error(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["check", "x=1,tilt=3"])
    assert exit_info.value.code == 2
    assert "'tilt=3' is not axis=value" in capsys.readouterr().err


def test_config_comes_from_the_environment_and_the_console_script_works(tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("name = 1\n")
    run = subprocess.run(
        [sys.executable, "-m", "hexactl.adapters.cli.main", "check"],
        capture_output=True, text=True, cwd=tmp_path,
        env={"PATH": "/usr/bin:/bin", CONFIG_ENVIRONMENT_VARIABLE: str(broken)},
    )
    assert run.returncode == 2
    assert f"{broken}: base_joints: Field required" in run.stderr
    default = subprocess.run([sys.executable, "-m", "hexactl.adapters.cli.main", "check"],
                             capture_output=True, text=True, cwd=tmp_path, env={"PATH": "/usr/bin:/bin"})
    # Outside the checkout the repository's config/platform.toml is the fallback.
    assert default.returncode == 0 and "12 of 12 poses reachable" in default.stdout


def test_fk_warns_near_a_singular_configuration(capsys) -> None:
    # Yaw 88°: the legs' readings have other poses close by (condition ≈ 230, limit 60).
    readings = ["754.1", "1019.0"] * 3
    assert main(["fk", *readings, "--json"]) == 1
    record = json.loads(capsys.readouterr().out)
    assert record["status"] == "ok" and record["near_singular"] and record["jacobian_condition"] > 200
    assert any(w.startswith("near-singular: Jacobian condition") for w in record["warnings"])
    assert main(["fk", *readings]) == 1
    out = capsys.readouterr().out
    assert "Jacobian condition" in out and "warning: near-singular" in out


def test_fk_warns_of_a_pose_outside_the_workspace_whose_readings_lie_inside_the_stroke(capsys) -> None:
    """Found from outside: readings inside the stroke whose pose lies outside the pose
    envelope (x 650 mm, the envelope ±610) were printed as a pose like any other."""
    assert main(["ik", "650", "0", "0", "0", "0", "0", "--json"]) == 1  # the pose is refused ...
    readings = json.loads(capsys.readouterr().out)["setpoints_mm"]
    assert main(["fk", *map(repr, readings), "--json"]) == 0  # ... its readings are a pose all the same
    record = json.loads(capsys.readouterr().out)
    assert record["warnings"] == ["outside the workspace: x 650 mm outside the pose envelope [-610, 610] mm (by 40 mm)"]
    assert main(["fk", *map(repr, readings)]) == 0
    assert "warning: outside the workspace: x 650 mm outside the pose envelope" in capsys.readouterr().out
    assert main(["ik", "600", "0", "0", "0", "0", "0", "--json"]) == 0
    inside = json.loads(capsys.readouterr().out)["setpoints_mm"]
    assert main(["fk", *map(repr, inside), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []  # inside: nothing to say


def test_fk_reports_the_condition_of_a_well_conditioned_pose(capsys) -> None:
    assert main(["fk", "317.6618", "421.2270", "513.9011", "559.2190", "514.5708", "447.7747", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert not record["near_singular"] and 1 < record["jacobian_condition"] < 60
