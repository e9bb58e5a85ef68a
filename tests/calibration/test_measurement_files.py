"""Measurement CSV files: both forms parse, every bad row is named by its line."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.files.measurements import (
    MeasurementFileError,
    format_measurements,
    parse_measurements,
    parse_point_rows,
    read_measurements,
    write_measurements,
)
from hexactl.calibration.data import MeasurementData, measured_poses, screen_measurements

HEADER_POINTS = "leg,l1,l2,l3,l4,l5,l6,p1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z"


def _points_text(campaign, rows=slice(0, 6)) -> str:
    data = campaign.data.select(np.isin(np.arange(len(campaign.data)), np.arange(len(campaign.data))[rows]))
    return format_measurements(data, comments=["test data"])


def test_points_form_round_trips_with_comments_and_line_numbers(leglock_campaign, tmp_path):
    path = write_measurements(tmp_path / "data.csv", leglock_campaign.data, comments=["first", "second"])
    parsed = read_measurements(path, feature_point_count=3)
    assert parsed.form == "points" and not parsed.problems and len(parsed.sha256) == 64
    assert np.allclose(parsed.data.points_mm, leglock_campaign.data.points_mm, atol=1e-6)
    assert np.allclose(parsed.data.readings_mm, leglock_campaign.data.readings_mm, atol=1e-6)
    assert np.array_equal(parsed.data.locked_leg, leglock_campaign.data.locked_leg)
    assert parsed.data.lines[0] == 4  # two comments and the header come first
    with pytest.raises(FileExistsError):
        write_measurements(path, leglock_campaign.data)


def test_pose_form_parses_degrees_into_radians(nominal, leglock_campaign):
    poses = measured_poses(leglock_campaign.data, np.array(nominal.measurement.feature_points)).poses
    data = MeasurementData(leglock_campaign.data.locked_leg, leglock_campaign.data.readings_mm,
                           leglock_campaign.data.lines, poses=poses)
    parsed = parse_measurements("# pose form\n\n" + format_measurements(data), "pose.csv", 3)
    assert parsed.form == "pose" and parsed.data.points_mm is None and not parsed.problems
    assert np.allclose(parsed.data.poses, poses, atol=1e-9)
    assert parsed.data.lines[0] == 4  # comment, blank line, header


def test_extra_columns_are_ignored_and_reported(leglock_campaign):
    text = _points_text(leglock_campaign)
    lines = text.splitlines()
    lines = [lines[0], lines[1] + ",operator"] + [line + ",anna" for line in lines[2:]]
    parsed = parse_measurements("\n".join(lines), "extra.csv", 3)
    assert parsed.ignored_columns == ("operator",) and len(parsed.data) == 6


@pytest.mark.parametrize("drop, missing", [("l4", "l4"), ("p3_z", "p3_z"), ("leg", "leg")])
def test_missing_columns_are_refused_by_name(leglock_campaign, drop, missing):
    text = _points_text(leglock_campaign)
    header_line, *rows = text.splitlines()[1:]
    columns = header_line.split(",")
    index = columns.index(drop)
    cut = [",".join(c for k, c in enumerate(row.split(",")) if k != index) for row in [header_line, *rows]]
    with pytest.raises(MeasurementFileError, match=f"missing columns {missing}"):
        parse_measurements("\n".join(cut), "cut.csv", 3)


@pytest.mark.parametrize("separator, decimal", [(";", ","), (";", "."), ("\t", ".")])
def test_a_spreadsheet_export_with_other_separators_is_refused_by_name(leglock_campaign, tmp_path, separator, decimal):
    """Excel in a decimal-comma locale writes ';' between columns (and a BOM and CRLF): the
    one-column header was reported as 'missing columns leg, l1, …', which hides the cause."""
    text = _points_text(leglock_campaign).replace(",", separator).replace(".", decimal).replace("\n", "\r\n")
    path = tmp_path / "excel.csv"
    path.write_bytes(text.encode("utf-8-sig"))
    expected = re.escape(f"line 2: the columns are separated by {separator!r}, not commas")
    with pytest.raises(MeasurementFileError, match=expected + ".*save the file as CSV with ','"):
        read_measurements(path, 3)
    with pytest.raises(MeasurementFileError, match=expected):  # a campaign's instrument file
        parse_point_rows(text, "tracker.csv", 3)
    path.write_bytes(_points_text(leglock_campaign).replace("\n", "\r\n").encode("utf-8-sig"))  # BOM, CRLF: fine
    parsed = read_measurements(path, 3)
    assert not parsed.problems and len(parsed.data) == 6


def test_too_few_or_too_many_points(leglock_campaign):
    with pytest.raises(MeasurementFileError, match="at least 3"):
        parse_measurements("leg,l1,l2,l3,l4,l5,l6,p1_x,p1_y,p1_z,p2_x,p2_y,p2_z\n", "two.csv", 3)
    with pytest.raises(MeasurementFileError, match="geometry defines 3"):
        parse_measurements(HEADER_POINTS + ",p4_x,p4_y,p4_z\n", "four.csv", 3)
    with pytest.raises(MeasurementFileError, match="no header"):
        parse_measurements("# only a comment\n\n", "empty.csv", 3)


def test_bad_values_are_reported_by_line_and_left_out(leglock_campaign):
    text = _points_text(leglock_campaign)  # line 1 comment, line 2 header, rows on lines 3-8
    lines = text.splitlines()
    fields = lines[3].split(",")
    fields[3] = "nan"
    lines[3] = ",".join(fields)  # line 4: NaN reading
    fields = lines[4].split(",")
    fields[9] = ""
    lines[4] = ",".join(fields)  # line 5: missing coordinate
    lines[5] = "9" + lines[5][1:]  # line 6: no such leg
    lines[6] = lines[6] + ",1.0"  # line 7: one field too many
    fields = lines[7].split(",")
    fields[2] = "abc"
    lines[7] = ",".join(fields)  # line 8: not a number
    parsed = parse_measurements("\n".join(lines), "bad.csv", 3)
    messages = {problem.line: problem.message for problem in parsed.problems}
    assert set(messages) == {4, 5, 6, 7, 8}
    assert "l3 is nan" in messages[4] and "p1_z is missing" in messages[5]
    assert "leg '9'" in messages[6] and "17 fields" in messages[7] and "'abc' is not a number" in messages[8]
    assert list(parsed.data.lines) == [3]


def test_screening_names_inconsistent_collinear_and_unlocked_rows(nominal, leglock_campaign):
    data = leglock_campaign.data
    points = np.array(data.points_mm)
    points[2, 1] += np.array([4.0, 0.0, 0.0])  # a mis-sighted target: distances disagree
    points[4] = points[4, 0] + np.outer([0.0, 1.0, 2.0], [300.0, 0.0, 0.0])  # collinear
    readings = np.array(data.readings_mm)
    leg = data.locked_leg[6]
    readings[6, leg - 1] += 0.5  # the "locked" leg moved
    bad = MeasurementData(data.locked_leg, readings, data.lines, points_mm=points)
    problems = screen_measurements(bad, np.array(nominal.measurement.feature_points), nominal.measurement.point_sigma_mm)
    by_line = {problem.line: str(problem) for problem in problems}
    assert set(by_line) == {int(data.lines[2]), int(data.lines[4]), int(data.lines[6])}
    assert "distance p1-p2" in by_line[int(data.lines[2])] and "tolerance" in by_line[int(data.lines[2])]
    assert "collinear" in by_line[int(data.lines[4])]
    assert f"leg {leg} is marked locked" in by_line[int(data.lines[6])]
    assert not screen_measurements(data, np.array(nominal.measurement.feature_points), nominal.measurement.point_sigma_mm)


def test_screening_names_readings_outside_the_stroke(nominal, leglock_campaign):
    data = leglock_campaign.data
    low, high = nominal.limits.stroke
    readings = np.array(data.readings_mm)
    readings[3, 2] = low - 50.0  # a typo no leg can make
    readings[5, 0] = high + 1.5
    readings[7, 4] = high + 0.5  # within the tolerance: noise at the stroke's end is not flagged
    bad = MeasurementData(data.locked_leg, readings, data.lines, points_mm=data.points_mm)
    feature_points = np.array(nominal.measurement.feature_points)
    problems = screen_measurements(bad, feature_points, nominal.measurement.point_sigma_mm, stroke_mm=(low, high))
    by_line = {problem.line: str(problem) for problem in problems if "stroke" in str(problem)}
    assert set(by_line) == {int(data.lines[3]), int(data.lines[5])}
    assert f"l3 reads {low - 50.0:.4f} mm, outside the actuators' stroke [{low:g}, {high:g}] mm" in by_line[int(data.lines[3])]
    assert "l1 reads" in by_line[int(data.lines[5])]
    assert not [p for p in screen_measurements(bad, feature_points, nominal.measurement.point_sigma_mm)
                if "stroke" in str(p)]  # without a stroke, nothing to check against


@pytest.mark.parametrize(("factor", "unit"), [(1e-3, "metres"), (0.1, "cm"), (1.0 / 25.4, "inches")])
def test_screening_names_readings_in_another_unit_once_for_the_file(nominal, leglock_campaign, factor, unit):
    data = leglock_campaign.data
    scaled = MeasurementData(data.locked_leg, np.array(data.readings_mm) * factor, data.lines, points_mm=data.points_mm)
    feature_points = np.array(nominal.measurement.feature_points)
    problems = screen_measurements(scaled, feature_points, nominal.measurement.point_sigma_mm,
                                   stroke_mm=nominal.limits.stroke, zero_readings_mm=nominal.zero_readings_mm())
    assert [problem.line for problem in problems] == [0]  # the file, not every row
    assert f"are they in {unit}? hexactl reads the sensors in mm" in str(problems[0])
    assert not screen_measurements(data, feature_points, nominal.measurement.point_sigma_mm,
                                   stroke_mm=nominal.limits.stroke, zero_readings_mm=nominal.zero_readings_mm())


@settings(max_examples=40, deadline=None)
@given(
    legs=st.lists(st.integers(0, 6), min_size=1, max_size=8),
    scale=st.floats(1e-3, 1e4),
    points=st.booleans(),
)
def test_any_data_round_trips_through_the_file_format(legs, scale, points):
    rng = np.random.default_rng(len(legs))
    count = len(legs)
    readings = rng.uniform(-1, 1, (count, 6)) * scale
    lines = np.arange(1, count + 1)
    if points:
        data = MeasurementData(np.array(legs), readings, lines, points_mm=rng.uniform(-1, 1, (count, 3, 3)) * scale)
    else:
        data = MeasurementData(np.array(legs), readings, lines, poses=rng.uniform(-1.5, 1.5, (count, 6)))
    parsed = parse_measurements(format_measurements(data, comments=["round trip"]), "rt.csv", 3)
    assert not parsed.problems and np.array_equal(parsed.data.locked_leg, data.locked_leg)
    assert np.allclose(parsed.data.readings_mm, readings, atol=1e-6)
    if points:
        assert np.allclose(parsed.data.points_mm, data.points_mm, atol=1e-6)
    else:
        assert np.allclose(parsed.data.poses, data.poses, atol=1e-9)


def _with_field(text: str, line: int, column: str, value: str) -> str:
    """``text`` with file line ``line``'s field of ``column`` replaced by ``value``."""
    lines = text.splitlines()
    header = next(entry for entry in lines if entry.startswith("leg,")).split(",")
    fields = lines[line - 1].split(",")
    fields[header.index(column)] = value
    lines[line - 1] = ",".join(fields)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("column", "value"), [("p1_y", "1_000"), ("leg", "１"), ("l2", "３５９.９"), ("p3_z", "٣"),
                                               ("p2_x", "0x10")])
def test_numbers_only_python_reads_are_refused_by_line_and_column(leglock_campaign, column, value):
    """Found in review: ``1_000`` and fullwidth digits passed through Python's float() and
    int(); no CSV writer produces them, so they are typing errors (plain ASCII only), in a
    measurement file and in a campaign's instrument file alike."""
    text = _with_field(_points_text(leglock_campaign), 5, column, value)  # rows on lines 3-8
    expected = [(5, f"{column} {value!r} is not a number (write digits 0-9 with an optional sign, '.' and exponent, "
                    "e.g. -12.5 or 1.2e3)")]
    parsed = parse_measurements(text, "typo.csv", 3)
    assert [(problem.line, problem.message) for problem in parsed.problems] == expected and 5 not in parsed.data.lines
    if column.startswith("p"):
        rows = parse_point_rows(text, "tracker.csv", 3)
        assert [(problem.line, problem.message) for problem in rows.problems] == expected


@pytest.mark.parametrize("value", ["+1.5", "-.5", "2.", "1E3", "-1.25e-2", " 7 "])
def test_plain_decimal_numbers_are_read(value):
    assert parse_point_rows(f"p1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z\n{value},0,0,1,0,0,0,1,0\n", "ok.csv",
                            3).points_mm[0, 0, 0] == float(value)


POSE_ROW = "leg,l1,l2,l3,l4,l5,l6,x,y,z,roll,pitch,yaw\n# one posture\n1,360,360,360,360,360,360,0,0,2000,0,0,0\n"


@pytest.mark.parametrize(("column", "value", "unit", "text"), [
    ("p1_y", "1e300", " mm", None), ("l4", "-2e6", " mm", None), ("p3_z", "1e999", " mm", None),
    ("roll", "5e6", "°", POSE_ROW), ("z", "1.5e6", " mm", POSE_ROW)])
def test_absurd_values_are_refused_by_line_and_column_as_a_typing_or_unit_error(leglock_campaign, column, value, unit,
                                                                                text):
    """Found in review: a finite 1e300 passed and crashed the fit (its square overflows)."""
    line = 3 if text else 6
    text = _with_field(text or _points_text(leglock_campaign), line, column, value)
    parsed = parse_measurements(text, "huge.csv", 3)
    assert [(problem.line, problem.message) for problem in parsed.problems] == [
        (line, f"{column} {value} is beyond ±1,000,000{unit}, far beyond any platform or instrument: a typing or unit "
            "error; correct the value")]


def test_a_decimal_comma_and_a_missing_header_are_named_as_such(leglock_campaign):
    """Found from outside: a quoted decimal comma got the generic hint on every field, and a
    file without a header line was told its columns were missing."""
    text = _with_field(_points_text(leglock_campaign), 5, "p1_y", '"437,659913"')
    parsed = parse_measurements(text, "comma.csv", 3)
    [(line, message)] = [(problem.line, problem.message) for problem in parsed.problems]
    assert line == 5 and message == ("p1_y '437,659913' is not a number: a decimal comma? (a spreadsheet's export in a "
                                     "locale that writes them: save it with '.' as the decimal mark)")
    headless = "\n".join(line for line in _points_text(leglock_campaign).splitlines()
                         if not line.startswith(("leg,", "#")))
    with pytest.raises(MeasurementFileError, match=r"^bare\.csv: line 1: numbers where the header belongs: the file "
                                                   r"has no header line; add one naming the columns"):
        parse_measurements(headless, "bare.csv", 3)
