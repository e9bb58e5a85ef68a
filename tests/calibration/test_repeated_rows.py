"""A measurement file with rows pasted or appended twice: each repeat is a row problem
naming the line it repeats (counted twice, it would claim a better calibration than the
data give); a posture measured again, however close, is not."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.measurements import write_measurements
from hexactl.calibration.data import MeasurementData, measured_poses, screen_measurements

from .conftest import NOMINAL_PATH


def _with_rows_again(data: MeasurementData, again: list[int], pose_form: bool) -> MeasurementData:
    """``data`` (in pose form if asked) followed by its rows ``again``, on the next lines."""
    rows = np.r_[np.arange(len(data)), again]
    lines = np.r_[data.lines, data.lines[-1] + 1 + np.arange(len(again))]
    measured = ({"poses": measured_poses(data, np.array(load_geometry(NOMINAL_PATH).measurement.feature_points))
                 .poses[rows]} if pose_form else {"points_mm": data.points_mm[rows]})
    return MeasurementData(data.locked_leg[rows], data.readings_mm[rows], lines, **measured)


def _repeats(data: MeasurementData, nominal) -> dict[int, str]:
    problems = screen_measurements(data, np.array(nominal.measurement.feature_points),
                                   nominal.measurement.point_sigma_mm)
    return {problem.line: problem.message for problem in problems if "repeats line" in problem.message}


@settings(max_examples=15)
@given(again=st.lists(st.integers(0, 59), min_size=1, max_size=5), pose_form=st.booleans())
def test_each_repeated_row_names_the_line_it_repeats(nominal, leglock_campaign, again, pose_form) -> None:
    data = _with_rows_again(leglock_campaign.data, again, pose_form)
    count = len(leglock_campaign.data)  # each appended row repeats its original, which comes first
    expected = {int(data.lines[count + k]): int(data.lines[row]) for k, row in enumerate(again)}
    found = _repeats(data, nominal)
    assert set(found) == set(expected)
    for line, first in expected.items():
        assert found[line].startswith(f"repeats line {first} exactly")


def test_a_posture_measured_again_is_not_a_repeat(nominal, leglock_campaign) -> None:
    data = _with_rows_again(leglock_campaign.data, [4], pose_form=False)
    readings = np.array(data.readings_mm)
    readings[-1, 2] += 1e-6  # the last digit a file keeps
    assert _repeats(MeasurementData(data.locked_leg, readings, data.lines, points_mm=data.points_mm), nominal) == {}
    assert _repeats(leglock_campaign.data, nominal) == {}


def test_calibrate_refuses_a_file_appended_to_itself_and_skips_the_repeats_when_told(tmp_path, leglock_campaign,
                                                                                      capsys) -> None:
    data = leglock_campaign.data
    twice = write_measurements(tmp_path / "twice.csv", _with_rows_again(data, list(range(len(data))), False))
    argv = ["calibrate", str(twice), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]
    assert main(argv) == 2
    assert "repeats line" in capsys.readouterr().err and not (tmp_path / "cal.toml").exists()
    assert main([*argv, "--skip-bad-rows"]) == 0
    assert load_geometry(tmp_path / "cal.toml").calibration.postures == len(data)
