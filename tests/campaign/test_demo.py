"""``hexactl demo``, reduced to two postures per leg: the real service path end to end, the
paper's tables, the exit status; and a calibration made worse on purpose is caught."""

from __future__ import annotations

import io
import shutil
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hexactl.application.campaign.store import (
    CALIBRATION_FILE,
    MEASUREMENTS_FILE,
    REPORT_DIRECTORY,
    VALIDATION_FILE,
)
from hexactl.adapters.cli.main import main
from hexactl.application.demo import clear_results
from hexactl.adapters.files.measurements import read_measurements, write_measurements
from hexactl.calibration.data import MeasurementData
from hexactl.kinematics.rotation import rotation_matrix

REDUCED = ["--per-leg", "2", "--envelope", "0.6",  # 12 postures, short moves: a minute and a half instead of two
           "--reset-faults", "20"]  # a loaded test host can stall the simulator past its actuators' watchdog


def demo(*arguments: str) -> SimpleNamespace:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = main(["demo", *arguments])
    return SimpleNamespace(status=status, out=out.getvalue(), err=err.getvalue())


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> SimpleNamespace:
    directory = tmp_path_factory.mktemp("demo") / "out"
    run = demo("--out", str(directory), *REDUCED)
    run.directory = directory
    return run


def test_the_demo_calibrates_and_prints_the_papers_tables(finished) -> None:
    assert finished.status == 0, finished.out + finished.err
    out = finished.out
    assert "hexactl demo (seed 0)" in out and "simulated theodolites, σ 0.25 mm" in out
    assert "postures [" in finished.err  # the progress bar
    lines = out.splitlines()
    table = lines.index("Table 1: compound motion from the zero posture")
    assert lines[table + 2].split()[1:] == ["100.00", "100.00", "100.00", "5.00", "5.00", "5.00"]
    before, after = (np.array(lines[table + k].split()[-6:], dtype=float) for k in (3, 4))
    command = np.array([100, 100, 100, 5, 5, 5])
    assert np.max(np.abs(after - command)[:3]) < np.max(np.abs(before - command)[:3]) / 5
    assert any(line.startswith("paper: before calibration") for line in lines)
    swept = next(line for line in lines if line.startswith("X sweep and Y rotation")).split()
    assert float(swept[8]) < float(swept[5]) / 5  # before % → after %, in the paper's terms
    assert next(line for line in lines if line.startswith("the paper")).split()[4:] == ["2.600", "%", "roll", "0.350", "%", "x"]
    assert "finished in" in lines[-1]
    # predicted accuracy beside the measured one, the instrument's noise in both
    measured = next(line for line in lines if line.strip().startswith("measured through the instrument")).split()
    predicted = next(line for line in lines if line.strip().startswith("predicted, calibration and instrument")).split()
    alone = next(line for line in lines if line.strip().startswith("predicted, calibration alone")).split()
    assert 0.5 < float(measured[4]) / float(predicted[4]) < 2.0  # position, mm
    assert float(alone[3]) < float(predicted[4])
    for name in (CALIBRATION_FILE, MEASUREMENTS_FILE, VALIDATION_FILE, f"{REPORT_DIRECTORY}/index.html",
                 f"{REPORT_DIRECTORY}/x_sweep.png", f"{REPORT_DIRECTORY}/y_rotation.png"):
        assert (finished.directory / name).exists(), name
    assert "true − identified" in (finished.directory / REPORT_DIRECTORY / "index.html").read_text()  # simulation


def test_a_finished_demo_is_kept_unless_forced(finished, tmp_path) -> None:
    refused = demo("--out", str(finished.directory), *REDUCED)
    assert refused.status == 2 and "finished campaign" in refused.err and "--force" in refused.err
    copy = tmp_path / "copy"
    shutil.copytree(finished.directory, copy)
    (copy / "notes.txt").write_text("mine")
    clear_results(copy)  # what --force does, without running a demo again
    assert sorted(path.name for path in copy.rglob("*") if path.is_file()) == ["notes.txt"]


def test_a_worse_calibration_is_rolled_back_and_the_exit_status_says_so(finished, tmp_path) -> None:
    """The theodolites, set up again after the test motions were measured, stood tilted by
    1.2° while the postures were measured: the data are consistent, so identification
    cannot tell, but the test motions measured after (instrument right again) show the
    platform worse than before. The demo resumes a copy of the finished one at that point."""
    directory = tmp_path / "tilted"
    shutil.copytree(finished.directory, directory)
    shutil.rmtree(directory / REPORT_DIRECTORY)
    (directory / CALIBRATION_FILE).unlink()
    rows = (directory / VALIDATION_FILE).read_text().splitlines()
    (directory / VALIDATION_FILE).write_text("\n".join(row for row in rows if not row.startswith("after,")) + "\n")
    measured = read_measurements(directory / MEASUREMENTS_FILE, 3).data
    pivot = np.array([0.0, 0.0, 2000.0])  # the zero posture's origin: the tilt moves the platform by degrees, not metres
    tilted = (measured.points_mm - pivot) @ rotation_matrix(np.radians(1.2), 0.0, 0.0).T + pivot
    write_measurements(directory / MEASUREMENTS_FILE, MeasurementData(measured.locked_leg, measured.readings_mm,
                                                                      measured.lines, points_mm=tilted), overwrite=True)
    run = demo("--out", str(directory), *REDUCED)
    assert run.status == 1, run.out + run.err
    assert "NOT improved" in run.out and "rolled back" in run.out and "did not improve" in run.out


def test_bad_demo_options_are_refused(tmp_path) -> None:
    assert demo("--out", str(tmp_path / "d"), "--per-leg", "0").status == 2
    assert demo("--out", str(tmp_path / "d"), "--envelope", "1.5").status == 2
    assert not Path(tmp_path / "d").exists()
