"""A measurement file whose header names the feature points' columns in the wrong order
(p1's coordinates under p2_x, p2_y, p2_z and the other way round): on a symmetric target
the points still have the right distances, so no row looks wrong, and a calibration went
on to joints a metre and a half off and a stroke error when saving. Screening names the
order that fits, for the whole file, or for one row whose targets were swapped."""

from __future__ import annotations

from itertools import permutations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.measurements import write_measurements
from hexactl.calibration.data import MeasurementData, screen_measurements

from .conftest import NOMINAL_PATH


def _reordered(data: MeasurementData, order: tuple[int, ...]) -> MeasurementData:
    """``data`` as a file whose column p{k+1} holds point ``order[k]`` reads."""
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=data.points_mm[:, list(order)])


def _screened(data: MeasurementData, nominal) -> list[str]:
    return [str(problem) for problem in screen_measurements(data, np.array(nominal.measurement.feature_points),
                                                            nominal.measurement.point_sigma_mm, legs=nominal.legs)]


@pytest.mark.parametrize("order", [order for order in permutations(range(3)) if order != (0, 1, 2)])
def test_points_in_another_order_are_one_problem_naming_the_order_that_fits(nominal, leglock_campaign, order) -> None:
    problems = _screened(_reordered(leglock_campaign.data, order), nominal)
    assert len(problems) == 1 and problems[0].startswith("the readings are "), problems
    # the file's column p{k+1} holds point order[k]: read back, column p{order[k]+1}... holds p{k+1}
    back = tuple(order.index(point) for point in range(3))
    for point, column in enumerate(back):
        assert (f"the columns named p{column + 1} hold p{point + 1}" in problems[0]) == (column != point), problems[0]
    assert "check the file's header" in problems[0]


def test_points_in_their_order_are_no_problem(nominal, leglock_campaign, noise_free_campaign) -> None:
    assert _screened(leglock_campaign.data, nominal) == []
    assert _screened(noise_free_campaign.data, nominal) == []


def test_calibrate_refuses_a_file_with_two_point_columns_swapped(tmp_path, leglock_campaign, capsys) -> None:
    data = write_measurements(tmp_path / "data.csv", leglock_campaign.data)
    lines = data.read_text().splitlines()
    header = next(number for number, line in enumerate(lines) if line.startswith("leg,"))
    lines[header] = lines[header].replace("p1_x,p1_y,p1_z,p2_x,p2_y,p2_z", "p2_x,p2_y,p2_z,p1_x,p1_y,p1_z")
    data.write_text("\n".join(lines) + "\n")
    assert main(["calibrate", str(data), "--config", str(NOMINAL_PATH), "-o", str(tmp_path / "cal.toml")]) == 2
    error = capsys.readouterr().err
    assert "the columns named p2 hold p1 and the columns named p1 hold p2" in error, error
    assert not (tmp_path / "cal.toml").exists()


@settings(max_examples=15, deadline=None)
@given(rows=st.lists(st.integers(0, 59), min_size=1, max_size=3, unique=True),
       order=st.sampled_from([order for order in permutations(range(3)) if order != (0, 1, 2)]))
def test_a_row_with_its_targets_swapped_is_a_problem_of_its_line(nominal, leglock_campaign, rows, order) -> None:
    """The distances of a symmetric target are right in any order, so nothing else flagged
    such a row, and `full` followed its upside-down pose to joints 1.8 m off."""
    data = leglock_campaign.data
    points = np.array(data.points_mm)
    points[rows] = points[rows][:, list(order)]
    problems = screen_measurements(MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=points),
                                   np.array(nominal.measurement.feature_points), nominal.measurement.point_sigma_mm,
                                   legs=nominal.legs)
    assert sorted(problem.line for problem in problems) == sorted(int(data.lines[row]) for row in rows), problems
    back = tuple(order.index(point) for point in range(3))
    swaps = " and ".join(f"the columns named p{column + 1} hold p{point + 1}"
                         for point, column in enumerate(back) if column != point)
    assert all(f"{swaps}: targets swapped?" in problem.message and not problem.mis_sighting for problem in problems)


def test_calibrate_refuses_a_row_with_its_targets_swapped_and_skips_it_when_told(tmp_path, nominal, leglock_campaign,
                                                                                 true_platform, capsys) -> None:
    data = leglock_campaign.data
    points = np.array(data.points_mm)
    points[20] = points[20][[1, 0, 2]]
    path = write_measurements(tmp_path / "data.csv", MeasurementData(data.locked_leg, data.readings_mm, data.lines,
                                                                     points_mm=points))
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 2
    error = capsys.readouterr().err
    assert "line 22: the readings are " in error and "targets swapped?" in error and not output.exists()  # header: line 1
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), "--skip-bad-rows"]) == 0
    calibrated = load_geometry(output)
    assert calibrated.calibration.postures == len(data) - 1
    assert np.max(np.abs(np.subtract(calibrated.base_joints, true_platform.base_joints))) < 3.0
