"""Measurement and posture-plan CSV files (mm and degrees).

Measurement file: one row per measured posture, header first, ``#`` comment lines and
blank lines allowed anywhere. Columns, in any order:

- ``leg``: the locked leg 1–6, 0 when none is locked;
- ``l1`` … ``l6``: sensor readings, mm;
- the measured posture, either ``x, y, z, roll, pitch, yaw`` (absolute: the moving frame in
  the fixed frame; mm, deg) or feature points ``p1_x, p1_y, p1_z, p2_x, …`` (fixed frame,
  mm; three or more, point k being the geometry's ``[measurement] feature_points[k]``).
  When both are present the points are used: they are the instrument's raw output.
- or the instrument's own observations of each point (read with the instrument's file,
  :mod:`hexactl.adapters.files.instrument_file`): two theodolites' angles ``p1_hz_a,
  p1_v_a, p1_hz_b, p1_v_b, p2_hz_a, …`` (horizontal and vertical, degrees), or a laser
  tracker's ``p1_range, p1_hz, p1_v, …`` (mm, degrees). Each point is then the one its
  observations imply, with its own covariance (:mod:`hexactl.calibration.observations`).

Other columns are ignored (and listed). A row with a missing, non-numeric or non-finite
value, a value beyond :data:`POSE_MAGNITUDE_LIMIT` or a bad leg number is reported by its line and
left out of the data; the caller decides whether that refuses the file. A number is plain
ASCII (:mod:`hexactl.kinematics.plain_numbers`): ``1_000`` or fullwidth digits are refused
as a typing error. Input files are only
read.

Instrument file (read by ``hexactl campaign --instrument csv:FILE``): the feature-point
columns alone, one row per measurement, in the order the campaign takes them.

Plan file (written by ``hexactl plan-leglock``): ``leg``, the relative pose ``x … yaw``
(mm, deg from the zero posture) and ``l1_setpoint`` … ``l6_setpoint`` (mm). Its set-point
columns are named so that a plan can never be mistaken for measurement data, nor a
measurement file's absolute poses for a plan's relative ones (:func:`parse_plan`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import os
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from math import isfinite
from pathlib import Path

import numpy as np

from hexactl.adapters.files.atomic import write_atomic
from hexactl.adapters.files.text import TextFileError, decode_text, read_problem
from hexactl.calibration.data import MeasurementData, RowProblem
from hexactl.calibration.observations import Instrument, Theodolites, point_covariance
from hexactl.calibration.planning import PosturePlan
from hexactl.kinematics.inverse import LEG_COUNT
from hexactl.kinematics.plain_numbers import PLAIN_DECIMAL, PLAIN_DECIMAL_HINT
from hexactl.kinematics.pose import pose_mm_deg_to_mm_rad, pose_mm_rad_to_mm_deg
from hexactl.kinematics.axes import POSE_AXES, POSE_MAGNITUDE_LIMIT

_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_ANGLE_SUFFIXES = ("roll", "pitch", "yaw", "hz", "v", "hz_a", "v_a", "hz_b", "v_b")

READING_COLUMNS = tuple(f"l{leg}" for leg in range(1, LEG_COUNT + 1))
SETPOINT_COLUMNS = tuple(f"l{leg}_setpoint" for leg in range(1, LEG_COUNT + 1))


class MeasurementFileError(ValueError):
    """The file as a whole cannot be used (unreadable, no header, missing columns)."""


@dataclass(frozen=True, slots=True, eq=False)
class MeasurementFile:
    """A parsed measurement file: the good rows as ``data``, the bad ones as ``problems``.

    ``form`` is "points" or "pose"; ``sha256`` hashes the file's bytes (it goes into the
    calibration file); ``ignored_columns`` were present but are not part of the format.
    """

    source: str
    data: MeasurementData
    problems: tuple[RowProblem, ...]
    form: str
    sha256: str
    ignored_columns: tuple[str, ...]


def read_measurements(path: str | os.PathLike[str], feature_point_count: int,
                      instrument: Instrument | None = None) -> MeasurementFile:
    """Read and parse a measurement file; ``feature_point_count`` is the geometry's number of
    feature points, ``instrument`` the one whose own observations the file may hold.
    Raises :class:`MeasurementFileError` naming the file and the problem."""
    location = Path(path)
    try:
        raw = location.read_bytes()
        text = decode_text(raw, str(location))
    except OSError as error:
        raise MeasurementFileError(f"{location}: {read_problem(error)}") from None
    except TextFileError as error:
        raise MeasurementFileError(str(error)) from None
    return parse_measurements(text, str(location), feature_point_count, hashlib.sha256(raw).hexdigest(), instrument)


def parse_measurements(text: str, source: str, feature_point_count: int, sha256: str = "",
                       instrument: Instrument | None = None) -> MeasurementFile:
    """Parse measurement CSV ``text`` (see the module docstring); ``instrument`` turns its
    own observations into points (needed when the file holds them)."""
    header_line, header, rows = _table(text, source)
    kind, observation_columns = _observation_columns(header)
    if observation_columns:
        _some_rows(rows, header_line, source)
        return _parse_observations(header_line, header, rows, source, feature_point_count, sha256, instrument, kind,
                                   observation_columns)
    point_columns = _point_columns(header)
    form = "points" if point_columns else "pose"
    pose_columns = [] if point_columns else list(POSE_AXES)
    required = ["leg", *READING_COLUMNS, *pose_columns, *(name for point in point_columns for name in point)]
    missing = [name for name in required if name not in header]
    if missing and all(PLAIN_DECIMAL.fullmatch(name.strip()) for name in header):
        raise MeasurementFileError(
            f"{source}: line {header_line}: numbers where the header belongs: the file has no header line; add one "
            "naming the columns: leg, l1 … l6 and either x, y, z, roll, pitch, yaw or p1_x, p1_y, p1_z … p3_z")
    if missing:
        raise MeasurementFileError(
            f"{source}: line {header_line}: missing columns {', '.join(missing)} (a row needs leg, l1 … l6 and either "
            "x, y, z, roll, pitch, yaw or feature points p1_x, p1_y, p1_z … p3_z)")
    _check_point_count(len(point_columns), source, feature_point_count)
    _some_rows(rows, header_line, source)
    used = set(required) | (set(POSE_AXES) if point_columns else set())
    ignored = tuple(name for name in header if name not in used)

    problems: list[RowProblem] = []
    legs, readings, lines, values = _good_rows(rows, header, required, [pose_columns] if pose_columns else point_columns,
                                               problems)
    count = len(legs)
    arrays = dict(locked_leg=np.array(legs, dtype=np.int64), readings_mm=np.array(readings).reshape(count, LEG_COUNT),
                  lines=np.array(lines, dtype=np.int64))
    if form == "points":
        data = MeasurementData(**arrays, points_mm=np.array(values).reshape(count, len(point_columns), 3))
    else:
        data = MeasurementData(**arrays, poses=pose_mm_deg_to_mm_rad(np.array(values).reshape(count, 6)))
    return MeasurementFile(source, data, tuple(problems), form, sha256, ignored)


@dataclass(frozen=True, slots=True, eq=False)
class PointRows:
    """An instrument's file of measured feature points, one row per measurement:
    ``points_mm`` (N, K, 3, fixed frame, mm) of the good rows and their source ``lines``;
    the bad rows as ``problems``."""

    points_mm: np.ndarray
    lines: tuple[int, ...]
    problems: tuple[RowProblem, ...]


def parse_point_rows(text: str, source: str, feature_point_count: int) -> PointRows:
    """Parse CSV ``text`` of measured points: a header naming ``p1_x, p1_y, p1_z, p2_x, …``
    (three feature points or more, at most ``feature_point_count``; other columns are
    ignored), ``#`` comments and blank lines anywhere. A row with a missing, non-numeric
    or non-finite value or the wrong number of fields is a problem of its line. Raises
    :class:`MeasurementFileError` when the file as a whole cannot be used."""
    header_line, header, rows = _table(text, source)
    point_columns = _point_columns(header)
    names = [name for point in point_columns for name in point]
    missing = [name for name in names if name not in header]
    if not point_columns or missing:
        raise MeasurementFileError(f"{source}: line {header_line}: missing columns "
                                   f"{', '.join(missing) or 'p1_x, p1_y, p1_z …'} (a row holds feature points "
                                   "p1_x, p1_y, p1_z, p2_x … in the fixed frame, mm)")
    _check_point_count(len(point_columns), source, feature_point_count)
    position = {name: index for index, name in enumerate(header)}
    points, lines, problems = [], [], []
    for number, line in rows:
        _, numbers, row_problems = _row(line, position, names)
        if row_problems:
            problems.append(RowProblem(number, "; ".join(row_problems)))
            continue
        points.append([[numbers[name] for name in point] for point in point_columns])
        lines.append(number)
    return PointRows(np.array(points, dtype=float).reshape(len(lines), len(point_columns), 3), tuple(lines),
                     tuple(problems))


def _table(text: str, source: str) -> tuple[int, list[str], list[tuple[int, str]]]:
    """(header line number, lower-cased column names, the data lines numbered) of CSV
    ``text`` without its comment and blank lines."""
    rows = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise MeasurementFileError(f"{source}: no header line and no data")
    header_line, header_text = rows[0]
    header = [name.strip().lower() for name in next(csv.reader([header_text]))]
    if len(header) == 1 and (separator := next((mark for mark in ";\t" if mark in header_text), None)):
        # A spreadsheet's export where the decimal mark is a comma: reading its numbers
        # would need guessing which comma is which, so it is refused by name.
        locale = " (a spreadsheet's export in a locale with decimal commas?)" if separator == ";" else ""
        raise MeasurementFileError(
            f"{source}: line {header_line}: the columns are separated by {separator!r}, not commas{locale}: save the "
            "file as CSV with ',' between columns and '.' as the decimal mark")
    duplicates = sorted({name for name in header if header.count(name) > 1})
    if duplicates:
        raise MeasurementFileError(f"{source}: line {header_line}: duplicate columns {', '.join(duplicates)}")
    return header_line, header, rows[1:]


def _some_rows(rows: list[tuple[int, str]], header_line: int, source: str) -> None:
    """A file without rows is bad input, not the identification's "insufficient data"."""
    if not rows:
        raise MeasurementFileError(f"{source}: a header (line {header_line}) but no postures: a measurement file holds "
                                   "a row per posture measured")


def _check_point_count(count: int, source: str, feature_point_count: int) -> None:
    if 0 < count < 3:
        raise MeasurementFileError(f"{source}: the file has {count} feature point(s); a posture needs at least 3")
    if count > feature_point_count:
        raise MeasurementFileError(
            f"{source}: the file has {count} feature points but the geometry defines "
            f"{feature_point_count} ([measurement] feature_points)")


def _row(line: str, position: dict[str, int], names: Sequence[str]) -> tuple[list[str], dict[str, float], list[str]]:
    """A data line's fields, the values of the columns ``names`` and a problem sentence per
    bad one (or the one problem of a line whose field count is not the header's)."""
    fields = next(csv.reader([line]))
    if len(fields) != len(position):
        return fields, {}, [f"has {len(fields)} fields, the header has {len(position)}"]
    numbers, problems = {}, []
    for name in names:
        value, problem = _number(fields[position[name]], name)
        if problem:
            problems.append(problem)
        numbers[name] = value
    return fields, numbers, problems


def _leg_problem(leg: float, field: str) -> str | None:
    """Why the ``leg`` column's value ``leg`` (read from ``field``) is not a leg number."""
    if leg == int(leg) and 0 <= leg <= LEG_COUNT:
        return None
    return f"leg {field.strip()!r} must be 0 (none locked) or a leg 1-{LEG_COUNT}"


OBSERVATION_COLUMNS = {"theodolites": ("hz_a", "v_a", "hz_b", "v_b"), "tracker": ("range", "hz", "v")}
"""Each instrument's columns per feature point (``p1_hz_a`` …); angles in degrees, range mm."""


def instrument_kind(instrument: Instrument) -> str:
    return "theodolites" if isinstance(instrument, Theodolites) else "tracker"


def _observation_columns(header: Sequence[str]) -> tuple[str, list[tuple[str, ...]]]:
    """The instrument whose observations the header holds and their columns per point."""
    for kind, names in OBSERVATION_COLUMNS.items():
        points: list[tuple[str, ...]] = []
        while any(f"p{len(points) + 1}_{name}" in header for name in names):
            points.append(tuple(f"p{len(points) + 1}_{name}" for name in names))
        if points:
            return kind, points
    return "", []


def _parse_observations(header_line: int, header: Sequence[str], rows: list[tuple[int, str]], source: str,
                        feature_point_count: int, sha256: str, instrument: Instrument | None, kind: str,
                        columns: list[tuple[str, ...]]) -> MeasurementFile:
    if instrument is None:
        raise MeasurementFileError(f"{source}: line {header_line}: the columns hold {kind} observations ({columns[0][0]} "
                                   "…): give the instrument's file (hexactl calibrate --instrument FILE), which says "
                                   "where it stood and its noise")
    if instrument_kind(instrument) != kind:
        raise MeasurementFileError(f"{source}: line {header_line}: the columns hold {kind} observations, the instrument "
                                   f"file describes {instrument_kind(instrument)}: give the instrument that took them")
    required = ["leg", *READING_COLUMNS, *(name for point in columns for name in point)]
    if missing := [name for name in required if name not in header]:
        raise MeasurementFileError(f"{source}: line {header_line}: missing columns {', '.join(missing)}")
    _check_point_count(len(columns), source, feature_point_count)
    problems: list[RowProblem] = []
    legs, readings, lines, values = _good_rows(rows, header, required, columns, problems)
    count = len(legs)
    observations = np.array(values, dtype=float).reshape(count, len(columns), instrument.size)
    angles = slice(0, 4) if kind == "theodolites" else slice(1, 3)
    observations[..., angles] = np.radians(observations[..., angles])
    try:
        points = instrument.points(observations)
    except ValueError as error:
        raise MeasurementFileError(f"{source}: {error}: check the instrument file's stations") from None
    data = MeasurementData(np.array(legs, dtype=np.int64), np.array(readings).reshape(count, LEG_COUNT),
                           np.array(lines, dtype=np.int64), points_mm=points,
                           point_covariance_mm2=point_covariance(instrument, points))
    ignored = tuple(name for name in header if name not in set(required))
    return MeasurementFile(source, data, tuple(problems), kind, sha256, ignored)


def format_observations(data: MeasurementData, observations: np.ndarray, instrument: Instrument,
                        comments: Sequence[str] = ()) -> str:
    """Measurement CSV text with the instrument's own ``observations`` (N, K, m; radians
    and mm) in place of the points."""
    kind = instrument_kind(instrument)
    header = ["leg", *READING_COLUMNS, *(f"p{k}_{name}" for k in range(1, observations.shape[1] + 1)
                                         for name in OBSERVATION_COLUMNS[kind])]
    shown = np.array(observations, dtype=float)
    angles = slice(0, 4) if kind == "theodolites" else slice(1, 3)
    shown[..., angles] = np.degrees(shown[..., angles])
    out = io.StringIO()
    for comment in comments:
        out.write(f"# {comment}\n")
    out.write(",".join(header) + "\n")
    for leg, reading, values in zip(data.locked_leg, data.readings_mm, shown.reshape(len(data), -1)):
        out.write(",".join([str(int(leg)), *(f"{v:.6f}" for v in reading), *(f"{v:.9f}" for v in values)]) + "\n")
    return out.getvalue()


def _good_rows(rows: Iterable[tuple[int, str]], header: Sequence[str], required: Sequence[str],
               groups: Sequence[Sequence[str]], problems: list[RowProblem]) -> tuple[list, list, list, list]:
    """The good rows' legs, readings, lines and values of each column group (a point's
    coordinates or observations, or the pose); the bad rows' problems into ``problems``."""
    position = {name: index for index, name in enumerate(header)}
    legs, readings, lines, values = [], [], [], []
    for number, leg, numbers in _valid_rows(rows, position, required, problems):
        legs.append(leg)
        readings.append([numbers[name] for name in READING_COLUMNS])
        lines.append(number)
        values.append([[numbers[name] for name in group] for group in groups])
    return legs, readings, lines, values


def _point_columns(header: Sequence[str]) -> list[tuple[str, str, str]]:
    """Column names of p1, p2, … as long as any coordinate of that point is present."""
    points = []
    while any(f"p{len(points) + 1}_{axis}" in header for axis in "xyz"):
        k = len(points) + 1
        points.append((f"p{k}_x", f"p{k}_y", f"p{k}_z"))
    return points


def _number(text: str, name: str) -> tuple[float, str | None]:
    """The value of column ``name``'s field ``text`` and why it cannot be used (None if it
    can): missing, not a plain ASCII decimal number, not finite or beyond
    :data:`POSE_MAGNITUDE_LIMIT`."""
    text = text.strip()
    if not text:
        return float("nan"), f"{name} is missing"
    if _NON_FINITE.fullmatch(text):
        return float(text), f"{name} is {text} (not a finite number)"
    if not PLAIN_DECIMAL.fullmatch(text):
        if PLAIN_DECIMAL.fullmatch(text.replace(",", ".", 1)):
            return float("nan"), (f"{name} {text!r} is not a number: a decimal comma? (a spreadsheet's export in a "
                                  "locale that writes them: save it with '.' as the decimal mark)")
        return float("nan"), f"{name} {text!r} is not a number ({PLAIN_DECIMAL_HINT})"
    value = float(text)
    if not isfinite(value) or abs(value) > POSE_MAGNITUDE_LIMIT:
        return value, (f"{name} {text} is beyond ±{POSE_MAGNITUDE_LIMIT:,.0f}{_unit(name)}, far beyond any platform or "
                       "instrument: a typing or unit error; correct the value")
    return value, None


def _unit(name: str) -> str:
    """Column ``name``'s unit as shown after a number."""
    if name == "leg":
        return ""
    return "°" if name in _ANGLE_SUFFIXES or name.partition("_")[2] in _ANGLE_SUFFIXES else " mm"


def format_measurements(data: MeasurementData, comments: Sequence[str] = ()) -> str:
    """Measurement CSV text for ``data`` (points form when it has points)."""
    header = ["leg", *READING_COLUMNS]
    if data.points_mm is not None:
        header += [f"p{k}_{axis}" for k in range(1, data.point_count + 1) for axis in "xyz"]
        posture = data.points_mm.reshape(len(data), -1)
        digits = 6
    else:
        assert data.poses is not None
        header += list(POSE_AXES)
        posture = pose_mm_rad_to_mm_deg(data.poses)
        digits = 9
    out = io.StringIO()
    for comment in comments:
        out.write(f"# {comment}\n")
    out.write(",".join(header) + "\n")
    for leg, reading, values in zip(data.locked_leg, data.readings_mm, posture):
        out.write(",".join([str(int(leg)), *(f"{v:.6f}" for v in reading), *(f"{v:.{digits}f}" for v in values)]) + "\n")
    return out.getvalue()


def write_measurements(path: str | os.PathLike[str], data: MeasurementData, *, overwrite: bool = False,
                       comments: Sequence[str] = ()) -> Path:
    """Write ``data`` atomically; refuses to replace a file unless ``overwrite``."""
    return write_atomic(path, format_measurements(data, comments).encode("utf-8"), overwrite=overwrite)


def format_plan(plan: PosturePlan, comments: Sequence[str] = ()) -> str:
    """Plan CSV text: leg, relative pose (mm, deg) and sensor set-points (mm)."""
    out = io.StringIO()
    for comment in comments:
        out.write(f"# {comment}\n")
    out.write(",".join(["leg", *POSE_AXES, *SETPOINT_COLUMNS]) + "\n")
    for pose, setpoints in zip(plan.poses_relative, plan.setpoints_mm):
        # Nine decimals: 1e-9° at the platform joints is 2e-8 mm, so the lock survives the round trip.
        out.write(",".join([str(plan.leg), *(f"{v:.9f}" for v in pose), *(f"{v:.6f}" for v in setpoints)]) + "\n")
    return out.getvalue()


def write_plan(path: str | os.PathLike[str], plan: PosturePlan, *, overwrite: bool = False,
               comments: Sequence[str] = ()) -> Path:
    """Write a plan atomically; refuses to replace a file unless ``overwrite``."""
    return write_atomic(path, format_plan(plan, comments).encode("utf-8"), overwrite=overwrite)


@dataclass(frozen=True, slots=True)
class PlanRows:
    """A parsed plan file: per good row its locked ``leg`` (0: none), relative pose (mm,
    deg) and source ``line``; the bad rows as ``problems``."""

    legs: tuple[int, ...]
    poses: tuple[tuple[float, ...], ...]
    lines: tuple[int, ...]
    problems: tuple[RowProblem, ...]


def _valid_rows(rows: Iterable[tuple[int, str]], position: dict[str, int], required: Sequence[str],
                problems: list[RowProblem]) -> Iterator[tuple[int, int, dict[str, float]]]:
    """(line, leg, values) of each row whose ``required`` values are finite numbers and
    whose leg is 1–6; each other row goes into ``problems`` with what is wrong with it."""
    for number, line in rows:
        fields, numbers, row_problems = _row(line, position, required)
        leg = numbers.get("leg", 0.0)
        if not row_problems and (problem := _leg_problem(leg, fields[position["leg"]])):
            row_problems.append(problem)
        if row_problems:
            problems.append(RowProblem(number, "; ".join(row_problems)))
            continue
        yield number, int(leg), numbers


def parse_plan(text: str, source: str) -> PlanRows:
    """Parse plan CSV ``text`` (:func:`format_plan`'s layout; ``#`` comments and blank
    lines anywhere, columns in any order, others ignored). A row with a missing,
    non-numeric or non-finite value or a bad leg is a problem of its line. Raises
    :class:`MeasurementFileError` when the file is not a plan at all."""
    header_line, header, rows = _table(text, source)
    required = ["leg", *POSE_AXES, *SETPOINT_COLUMNS]
    missing = [name for name in required if name not in header]
    if missing:
        raise MeasurementFileError(
            f"{source}: line {header_line}: not a posture plan: missing columns {', '.join(missing)} (a plan, as "
            "`hexactl plan-leglock` writes it, has leg, x, y, z, roll, pitch, yaw and l1_setpoint … l6_setpoint)")
    position = {name: index for index, name in enumerate(header)}
    legs, poses, lines, problems = [], [], [], []
    for number, leg, numbers in _valid_rows(rows, position, required, problems):
        legs.append(leg)
        poses.append(tuple(numbers[name] for name in POSE_AXES))
        lines.append(number)
    return PlanRows(tuple(legs), tuple(poses), tuple(lines), tuple(problems))
