"""The calibration commands end to end, through ``hexactl.adapters.cli.main.main``."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.measurements import format_measurements, write_measurements
from hexactl.kinematics.inverse import leg_lengths_batch
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.workspace import assess_poses

from .conftest import NOMINAL_PATH


@pytest.fixture
def data_file(tmp_path, leglock_campaign):
    return write_measurements(tmp_path / "data.csv", leglock_campaign.data, comments=["simulated"])


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_calibrate_writes_a_reloadable_file_and_refuses_to_overwrite(tmp_path, data_file, nominal, true_platform, capsys):
    output = tmp_path / "cal.toml"
    before = _sha(data_file)
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 0
    out = capsys.readouterr().out
    assert "auto chose full" in out and f"wrote {output}" in out
    calibrated = load_geometry(output)
    assert calibrated.calibration is not None and calibrated.calibration.method == "full"
    assert calibrated.calibration.input_sha256 == before and calibrated.calibration.postures == 60
    assert calibrated.limits == nominal.limits and calibrated.home == nominal.home
    errors = np.subtract(calibrated.platform_joints, true_platform.platform_joints)
    assert np.max(np.abs(errors)) < 5 * np.max(calibrated.calibration.platform_joints_std_mm)
    assert _sha(data_file) == before  # input never modified

    written = output.read_bytes()
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err and output.read_bytes() == written
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(output), "--force",
                 "--method", "leglock"]) == 0
    assert load_geometry(output).calibration.method == "leglock"


def test_a_file_with_a_header_and_no_postures_is_bad_input(tmp_path, data_file, capsys):
    """Found from outside: it exited 1, "insufficient data … the data have 0", as a fit that
    failed; it is a file to fix (exit 2), as play says of a plan without rows."""
    header_only = tmp_path / "header_only.csv"
    lines = data_file.read_text().splitlines()
    header = next(number for number, line in enumerate(lines, start=1) if line.strip() and not line.startswith("#"))
    header_only.write_text("\n".join(lines[:header]) + "\n")
    assert main(["calibrate", str(header_only), "-o", str(tmp_path / "cal.toml")]) == 2
    assert f"{header_only}: a header (line {header}) but no postures: a measurement file holds a row per posture " \
           "measured" in capsys.readouterr().err
    assert not (tmp_path / "cal.toml").exists()


def test_no_command_writes_over_its_own_input_even_with_force(tmp_path, data_file, capsys):
    """A measurement file is hours of measuring: -o naming it (or the geometry read) is a
    slip, refused before any work, whatever --force says."""
    before = _sha(data_file)
    config = tmp_path / "platform.toml"
    config.write_bytes(NOMINAL_PATH.read_bytes())
    (tmp_path / "link.csv").symlink_to(data_file)
    for argv in (
        ["calibrate", str(data_file), "--config", str(config), "-o", str(data_file), "--force"],
        ["calibrate", str(data_file), "--config", str(config), "-o", str(tmp_path / "link.csv"), "--force"],
        ["calibrate", str(data_file), "--config", str(config), "-o", str(config), "--force"],
        ["plan-leglock", "--leg", "1", "--count", "8", "--config", str(config), "-o", str(config), "--force"],
        ["simulate-campaign", "--config", str(config), "-o", str(config), "--force"],
        ["simulate-campaign", "--config", str(config), "-o", str(data_file), "--true-output", str(data_file), "--force"],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "never written over" in err or "is the measurement file too: name two files" in err, (argv, err)
    assert _sha(data_file) == before and config.read_bytes() == NOMINAL_PATH.read_bytes()


def test_report_with_simulated_validation(tmp_path, data_file, true_platform):
    true_path = tmp_path / "true.toml"
    from hexactl.adapters.files.geometry_file import save_geometry

    save_geometry(true_platform, true_path)
    report = tmp_path / "report"
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml"),
                 "--report", str(report), "--true", str(true_path)]) == 0
    page = (report / "index.html").read_text(encoding="utf-8")
    for name in ("residuals.png", "parameters.png", "observability.png", "x_sweep.png", "y_rotation.png",
                 "accuracy_map.png"):
        assert (report / name).read_bytes().startswith(b"\x89PNG")
    assert "Validation" in page and "paper: after calibration" in page and "data:image/png;base64," in page
    assert "Predicted accuracy over the workspace" in page
    # per axis, and the radius the controller reports beside it: not one read as the other
    assert "predicted pose uncertainty on the test motions, per axis" in page
    assert "as a radius √(σx² + σy² + σz²), what status" in page and "predicted_accuracy.position_mm gives" in page

    # Again into the same folder without --true: the first calibration's validation plots
    # are not left beside a report that has none, passing for this calibration's.
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml"),
                 "--report", str(report), "--force"]) == 0
    assert "Validation" not in (report / "index.html").read_text(encoding="utf-8")
    assert sorted(path.name for path in report.iterdir()) == ["accuracy_map.png", "index.html", "observability.png",
                                                               "parameters.png", "residuals.png"]


def test_a_failed_identification_writes_its_report_and_predicts_no_accuracy(tmp_path, leglock_campaign, capsys,
                                                                           recwarn):
    """Found from outside: with one posture measured sixty times ("not observable") the
    report was not written (what would show why), and 0.023 mm was printed as the predicted
    accuracy, better than a good campaign's, from a fit with 36 undetermined combinations."""
    header, first = [line for line in format_measurements(leglock_campaign.data).splitlines()
                     if not line.startswith("#")][:2]
    points = [k for k, name in enumerate(header.split(",")) if name.startswith("p")]
    rng = np.random.default_rng(3)
    rows = []
    for _ in range(30):  # the one posture measured again and again: the points' noise anew each time
        fields = first.split(",")
        for k in points:
            fields[k] = f"{float(fields[k]) + rng.normal(0.0, 0.25):.4f}"
        rows.append(",".join(fields))
    path = tmp_path / "one_posture.csv"
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    report, output = tmp_path / "report", tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), "--report", str(report)]) == 1
    out = capsys.readouterr().out
    assert "status: not observable" in out and "no calibration written: not observable" in out
    assert "predicted pose uncertainty on the paper's test motions: not predicted (the data do not determine every " \
           "parameter)" in out
    page = (report / "index.html").read_text(encoding="utf-8")
    assert "not observable: no calibration file was written" in page and "not predicted: the data do not" in page
    assert not output.exists() and f"wrote {report / 'index.html'}" in out
    few = tmp_path / "few.csv"  # too few to fit at all: a report of nothing determined, drawn without warnings
    few.write_text("\n".join([header, *rows[:3]]) + "\n", encoding="utf-8")
    assert main(["calibrate", str(few), "--config", str(NOMINAL_PATH), "-o", str(output), "--report",
                 str(tmp_path / "few")]) == 1
    assert "no calibration written: insufficient data" in capsys.readouterr().out
    assert not [w for w in recwarn if issubclass(w.category, (RuntimeWarning, UserWarning))], \
        [str(w.message) for w in recwarn]


def test_the_report_may_not_be_the_calibration_files_path_and_options_a_method_ignores_are_named(tmp_path, data_file,
                                                                                              capsys):
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(output),
                 "--report", str(output)]) == 2
    assert "is the calibration file's own path (-o)" in capsys.readouterr().err and not output.exists()
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(output), "--method", "full",
                 "--loss", "cauchy"]) == 0
    assert "note: --loss applies to --method leglock and auto (auto: when it takes leglock); --method full does not " \
           "use it" in capsys.readouterr().err


def test_a_large_campaign_is_said_to_take_a_while_before_the_work_starts(tmp_path, data_file, capsys, monkeypatch):
    """Found from outside: 51,000 rows ran two minutes and 2 GB with nothing printed."""
    from hexactl.adapters.cli import calibration_commands

    monkeypatch.setattr(calibration_commands, "LARGE_CAMPAIGN_POSTURES", 60)  # the fixture's 60 stand for thousands
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]) == 0
    assert "hexactl calibrate: identifying from 60 postures: this takes a while" in capsys.readouterr().err
    monkeypatch.setattr(calibration_commands, "LARGE_CAMPAIGN_POSTURES", 61)
    assert main(["calibrate", str(data_file), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml"),
                 "--force"]) == 0
    assert "takes a while" not in capsys.readouterr().err


def test_bad_rows_are_refused_by_line_or_skipped_on_request(tmp_path, leglock_campaign, capsys):
    lines = format_measurements(leglock_campaign.data).splitlines()
    fields = lines[5].split(",")
    fields[2] = "NaN"
    lines[5] = ",".join(fields)  # file line 6
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 2
    err = capsys.readouterr().err
    assert "line 6: l2 is NaN" in err and "--skip-bad-rows" in err and not output.exists()
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), "--skip-bad-rows"]) == 0
    assert "excluded 1 row" in capsys.readouterr().out
    assert load_geometry(output).calibration.postures == 59


def test_too_few_locked_postures_for_leglock_names_the_lines(tmp_path, leglock_campaign, capsys):
    data = leglock_campaign.data
    keep = (data.locked_leg != 2) | (np.cumsum(data.locked_leg == 2) <= 3)
    path = write_measurements(tmp_path / "few.csv", data.select(keep))
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "c.toml"),
                 "--method", "leglock"]) == 1
    out = capsys.readouterr().out
    assert "leg 2 has 3 locked posture(s) (lines 12, 13, 14)" in out and "no calibration written" in out


def test_plan_leglock_file_holds_the_lock_and_the_limits(tmp_path, nominal, capsys):
    plan_path = tmp_path / "plan.csv"
    assert main(["plan-leglock", "--config", str(NOMINAL_PATH), "--leg", "5", "--count", "8",
                 "--candidates", "300", "--reading", "380", "-o", str(plan_path)]) == 0
    header, *rows = [line for line in plan_path.read_text().splitlines() if not line.startswith("#")]
    table = np.array([[float(v) for v in row.split(",")] for row in rows])
    assert header.startswith("leg,x,y,z,roll,pitch,yaw,l1_setpoint")
    assert np.all(table[:, 0] == 5) and len(table) == 8
    lengths = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, table[:, 1:7]))
    assert np.max(np.abs(lengths[:, 4] - (nominal.zero_lengths[4] + 380.0))) < 1e-6
    assert all(assessment.ok for assessment in assess_poses(nominal, table[:, 1:7]))
    assert np.allclose(table[:, 7:], lengths - np.array(nominal.zero_lengths), atol=1e-5)

    assert main(["plan-leglock", "--config", str(NOMINAL_PATH), "--leg", "1", "--count", "3", "--candidates", "100"]) == 0
    assert capsys.readouterr().out.count("\n1,") == 3
    assert main(["plan-leglock", "--config", str(NOMINAL_PATH), "--leg", "8", "--count", "3"]) == 2
    capsys.readouterr()
    for lock in (["--reading", "2000"], ["--reading", "-5"], ["--length", "10"]):  # where no leg can be
        assert main(["plan-leglock", "--config", str(NOMINAL_PATH), "--leg", "2", "--count", "3", *lock]) == 2
        assert "leg 2 cannot be locked there: outside its stroke [0, 850] mm" in capsys.readouterr().err, lock
    # Found from outside: inside the stroke but within its margin, no posture is feasible, and the
    # advice was to raise --candidates, which cannot help.
    assert main(["plan-leglock", "--config", str(NOMINAL_PATH), "--leg", "1", "--count", "5", "--reading", "849"]) == 1
    assert ("the locked reading 849.000 mm lies within the stroke's 10 mm margin ([0, 850] mm): lock the leg between "
            "10 and 840 mm") in capsys.readouterr().err
    # ... and simulate-campaign, which has no --candidates, was told to give more of them
    with pytest.raises(SystemExit) as refused:
        main(["simulate-campaign", "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "x.csv"), "--per-leg", "100000"])
    assert refused.value.code == 2
    assert "argument --per-leg: '100000' is not a whole number from 0 to 1500" in capsys.readouterr().err


def test_simulate_campaign_then_calibrate_pose_form(tmp_path, capsys):
    data, true = tmp_path / "sim.csv", tmp_path / "true.toml"
    assert main(["simulate-campaign", "--config", str(NOMINAL_PATH), "-o", str(data), "--true-output", str(true),
                 "--per-leg", "8", "--seed", "4", "--pose-form"]) == 0
    assert "x,y,z,roll,pitch,yaw" in data.read_text()
    assert main(["calibrate", str(data), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]) == 0
    calibrated, truth = load_geometry(tmp_path / "cal.toml"), load_geometry(true)
    assert np.max(np.abs(np.subtract(calibrated.zero_lengths, truth.zero_lengths))) < 3.0
    assert "status: ok" in capsys.readouterr().out


def test_points_in_metres_are_named_once_and_refused(tmp_path, leglock_campaign, capsys):
    data = leglock_campaign.data
    metres = type(data)(data.locked_leg, data.readings_mm, data.lines, points_mm=np.array(data.points_mm) / 1000.0)
    path = write_measurements(tmp_path / "metres.csv", metres)
    output = tmp_path / "cal.toml"
    for extra in ([], ["--skip-bad-rows"]):  # no row to skip: the whole file is in the wrong unit
        assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("are they in metres? hexactl reads mm") == 1 and "collinear" not in err
        assert not output.exists()


def test_readings_in_metres_are_named_once_and_refused(tmp_path, leglock_campaign, capsys):
    data = leglock_campaign.data
    metres = type(data)(data.locked_leg, np.array(data.readings_mm) / 1000.0, data.lines, points_mm=data.points_mm)
    path = write_measurements(tmp_path / "metres.csv", metres)
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 2
    err = capsys.readouterr().err
    assert err.count("are they in metres? hexactl reads the sensors in mm") == 1, err
    assert not output.exists()


@pytest.mark.filterwarnings("error")  # a library warning fails the test
def test_undetermined_data_give_no_library_warning_and_say_why(tmp_path, leglock_campaign, capsys):
    """One posture measured 60 times: most combinations undetermined. Nothing but hexactl's
    own messages reaches stderr (numpy's "covariance is not symmetric positive-semidefinite"
    came from rounding in a barely determined covariance). Each measurement differs in its
    readings' last digit, as measured again, not pasted (screening refuses exact repeats)."""
    data = leglock_campaign.data
    first = np.zeros(len(data), dtype=int)
    readings = data.readings_mm[first] + 1e-6 * np.arange(len(data))[:, None]
    same = type(data)(data.locked_leg[first], readings, data.lines, points_mm=data.points_mm[first])
    path = write_measurements(tmp_path / "same.csv", same)
    code = main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")])
    captured = capsys.readouterr()
    assert code == 1 and "cannot determine" in captured.out and "no calibration written" in captured.out
    assert "Warning" not in captured.err


def test_a_file_with_no_usable_row_says_so_without_a_traceback(tmp_path, leglock_campaign, capsys):
    """An export whose every row is bad and skipped leaves no posture: the screening of
    repeated rows crashed on it (reshape of an empty array). (One with only its header is
    bad input: test_a_file_with_a_header_and_no_postures_is_bad_input.)"""
    lines = format_measurements(leglock_campaign.data).splitlines()
    header, rows = lines[0], lines[1:]
    body = [",".join(["9", *row.split(",")[1:]]) for row in rows]  # leg 9
    path = tmp_path / "empty.csv"
    path.write_text("\n".join([header, *body]) + "\n", encoding="utf-8")
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), "--skip-bad-rows"]) == 1
    out = capsys.readouterr().out
    assert "needs at least 8 postures, the data have 0" in out and "no calibration written" in out
    assert not output.exists()


@pytest.mark.parametrize("method", ["auto", "leglock"])
def test_an_absurd_coordinate_is_refused_by_line_and_column_without_a_traceback(tmp_path, leglock_campaign, capsys,
                                                                                method):
    """Found in review: p1_y written 1e300, finite, crashed `calibrate` in the fit (scipy:
    "Residuals are not finite in the initial point")."""
    lines = format_measurements(leglock_campaign.data).splitlines()
    fields = lines[20].split(",")
    fields[8] = "1e300"  # p1_y of file line 21
    lines[20] = ",".join(fields)
    path = tmp_path / "huge.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    calibrate = ["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml"),
                 "--method", method]
    assert main(calibrate) == 2
    assert (f"{path}: line 21: p1_y 1e300 is beyond ±1,000,000 mm, far beyond any platform or instrument: a typing "
            "or unit error; correct the value") in capsys.readouterr().err
    assert main([*calibrate, "--skip-bad-rows"]) == 0
    captured = capsys.readouterr()
    assert "line 21: p1_y 1e300" in captured.err and "excluded 1 row(s)" in captured.out
