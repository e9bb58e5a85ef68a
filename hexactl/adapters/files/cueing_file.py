"""Motion cueing files: the parameters (TOML) and a vehicle trajectory (CSV).

The parameters file is ``config/cueing.toml``'s format: tables ``[translational]``,
``[rotational]``, ``[tilt]`` and ``[workspace]`` of
:class:`~hexactl.cueing.parameters.CueingParameters`; a key left out keeps its default.

A vehicle trajectory is CSV with a header naming the columns (any order; others ignored)::

    t_s,f_x,f_y,f_z,omega_x,omega_y,omega_z
    0.00,0.000000,0.000000,9.810000,0.000000,0.000000,0.000000
    0.01,...

``t_s`` in s, evenly spaced: the period is taken from the first time to the last, and
each time may be off that even spacing by as much as the text's rounding of it (its
decimals); ``f_*`` the specific force (m/s², body axes x forward, y left, z up: (0, 0,
9.81) at rest) and ``omega_*`` the angular rate (rad/s). Every error names the file, the
line and the column, and what to do.
"""

from __future__ import annotations

import csv
import io
import os
import tomllib
from decimal import Decimal
from math import isfinite
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from hexactl.adapters.files.config_path import SHIPPED_VEHICLES
from hexactl.adapters.files.text import read_text
from hexactl.cueing.parameters import CueingParameters
from hexactl.cueing.washout import GRAVITY_M_S2, VehicleTrajectory
from hexactl.kinematics.plain_numbers import PLAIN_DECIMAL, PLAIN_DECIMAL_HINT
from hexactl.kinematics.validation_messages import accepted_keys, unknown_key_message, validation_location

VEHICLE_COLUMNS = ("t_s", "f_x", "f_y", "f_z", "omega_x", "omega_y", "omega_z")

PERIOD_TOLERANCE = 1e-3
"""How far, as a fraction of the sample period, a time may be off the file's even spacing
beyond the text's rounding of it (:func:`_resolution`): the floats' own rounding of large
times (1e9 s to 1e-7 s), not a change of rate."""

F_Z_RANGE_G = (0.5, 1.5)
"""Where the median of ``f_z`` lies, in g: a car or an aircraft spends most of its time
near 1 g. A median near 1, 0 or −9.81 m/s² is a file in g, an acceleration without
gravity, or z-down (aerospace) axes, and the washout would cue a jolt of about 1 g."""


MAX_SPECIFIC_FORCE_M_S2 = 30 * GRAVITY_M_S2
"""Largest specific force on an axis, m/s²: 30 g, beyond any vehicle a motion platform
cues (a crash pulse aside). A larger value is a unit mistake or a glitch: one spike of
10⁶ m/s² had made the workspace gain 0 and silenced every cue, and 1e308 overflowed the
filter."""

MAX_ANGULAR_RATE_RAD_S = 35.0
"""Largest angular rate on an axis, rad/s: 2000 deg/s, a vehicle gyro's usual full scale."""

NOTED_ANGULAR_RATE_RAD_S = 6.0
"""An angular rate beyond this (about 340 deg/s) is noted, not refused: a car, a ship or an
airliner turns far slower, an aerobatic aircraft or a crash test may not, and a file in
deg/s read as rad/s (30 deg/s taken for 30 rad/s, found from outside) looks the same."""


class CueingFileError(ValueError):
    """A cueing file could not be read; the message names the file, where, and the problem."""


def parse_cueing_parameters(text: str, source: str) -> CueingParameters:
    """Validate TOML text into :class:`CueingParameters`; :class:`CueingFileError` names
    every problem as ``source: table.key[index]: problem``."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as error:  # RecursionError: arrays nested 1000 deep
        raise CueingFileError(f"{source}: not valid TOML: {error}") from None
    try:
        return CueingParameters.model_validate(data)
    except ValidationError as error:
        raise CueingFileError(_describe(error, source)) from None


def load_cueing_parameters(path: str | os.PathLike[str]) -> CueingParameters:
    """Read a parameters file; :class:`CueingFileError` names the file, key and problem."""
    return parse_cueing_parameters(read_text(path, CueingFileError), str(path))


def _describe(error: ValidationError, source: str) -> str:
    """One line per problem, ``source: table.key[index]: what is wrong and what to do``."""
    lines = []
    for problem in error.errors():
        where = list(problem["loc"])
        message = problem["msg"].removeprefix("Value error, ")
        if problem["type"] == "extra_forbidden":
            message = unknown_key_message(where[-1], accepted_keys(CueingParameters, where))
        elif problem["type"] == "finite_number":
            message = "must be a finite number (NaN and inf are refused)"
        elif problem["type"] == "missing" and where and isinstance(where[-1], int):  # a list one value short
            message = f"too few values, one per axis as in config/cueing.toml (value {where.pop() + 1} is missing)"
        elif problem["type"] == "too_long":
            message = "too many values, one per axis as in config/cueing.toml"
        elif problem["type"] == "tuple_type":
            message = "must be a list of numbers, one per axis as in config/cueing.toml"
        location = validation_location(where)
        lines.append(f"{source}: {location}: {message}" if location else f"{source}: {message}")
    return "\n".join(lines)


def parse_vehicle_trajectory(text: str, source: str) -> VehicleTrajectory:
    """Validate CSV text into a :class:`VehicleTrajectory`; :class:`CueingFileError` names
    the first problem's line and column."""
    rows = csv.reader(io.StringIO(text))
    header = next(rows, None)
    if header is None:
        raise CueingFileError(f"{source}: empty: a vehicle trajectory needs the header {','.join(VEHICLE_COLUMNS)}")
    names = [name.strip() for name in header]
    missing = [column for column in VEHICLE_COLUMNS if column not in names]
    if missing:
        unknown = [name for name in names if name not in VEHICLE_COLUMNS]
        hint = f" (the header has {', '.join(unknown)} instead: check the spelling)" if unknown else ""
        raise CueingFileError(f"{source}: line 1: missing column {', '.join(missing)}{hint}; the header must name "
                              f"{','.join(VEHICLE_COLUMNS)}")
    if twice := sorted({name for name in names if name in VEHICLE_COLUMNS and names.count(name) > 1}):
        raise CueingFileError(f"{source}: line 1: column {', '.join(twice)} named more than once: which is meant "
                              "cannot be told; keep one")
    where = [names.index(column) for column in VEHICLE_COLUMNS]
    values, lines, written_times = [], [], []
    for line, row in enumerate(rows, start=2):
        if any(cell.strip() for cell in row):
            if len(row) != len(names):  # a value too many or too few shifts the others to another column
                raise CueingFileError(f"{source}: line {line}: has {len(row)} fields, the header has {len(names)}")
            values.append([_plausible(_number(row, index, column, line, source), column, line, source)
                           for index, column in zip(where, VEHICLE_COLUMNS)])
            lines.append(line)
            written_times.append(row[where[0]].strip())
    if len(values) < 2:
        raise CueingFileError(f"{source}: {len(values)} samples: a vehicle trajectory needs at least two lines of values")
    table = np.array(values)
    _check_gravity(table[:, 3], source)
    period_s = _uniform_period(table[:, 0], _resolution(written_times), lines, source)
    return VehicleTrajectory(period_s=period_s, specific_force=table[:, 1:4], angular_rate=table[:, 4:7])


def load_vehicle_trajectory(path: str | os.PathLike[str]) -> VehicleTrajectory:
    """Read a vehicle trajectory file, or a shipped one by its name (``braking``,
    ``lane_change``: :func:`shipped_vehicles`) when no such file exists;
    :class:`CueingFileError` names the file, line and column."""
    shipped = SHIPPED_VEHICLES / f"{path}.csv"
    if not Path(path).exists() and Path(path).name == str(path) and shipped.is_file():
        path = shipped
    elif not Path(path).exists():
        raise CueingFileError(f"{path}: no such file; the shipped trajectories are {', '.join(shipped_vehicles())} "
                              f"(by name), in {SHIPPED_VEHICLES}")
    return parse_vehicle_trajectory(read_text(path, CueingFileError), str(path))


def shipped_vehicles() -> list[str]:
    """The names of the vehicle trajectories hexactl ships."""
    return sorted(path.stem for path in SHIPPED_VEHICLES.glob("*.csv"))


def angular_rate_note(vehicle: VehicleTrajectory, source: str) -> str | None:
    """A note when ``vehicle`` turns faster than :data:`NOTED_ANGULAR_RATE_RAD_S` on an axis:
    perhaps deg/s; None otherwise."""
    peaks = np.max(np.abs(vehicle.angular_rate), axis=0)
    axis = int(np.argmax(peaks))
    if peaks[axis] <= NOTED_ANGULAR_RATE_RAD_S:
        return None
    return (f"{source}: column omega_{'xyz'[axis]} reaches {peaks[axis]:g} rad/s ({np.degrees(peaks[axis]):.0f} deg/s), "
            f"faster than a road vehicle, a ship or an airliner turns: if the file is in deg/s, multiply omega_* by "
            "π/180 (the washout reads rad/s)")


def _number(row: list[str], index: int, column: str, line: int, source: str) -> float:
    cell = row[index].strip() if index < len(row) else ""
    value = float(cell) if PLAIN_DECIMAL.fullmatch(cell) else float("nan")
    if not isfinite(value):
        shown = f"'{cell}'" if cell else "nothing"
        raise CueingFileError(f"{source}: line {line}, column {column}: {shown} is not a finite number "
                              f"({PLAIN_DECIMAL_HINT})")
    return value


def _plausible(value: float, column: str, line: int, source: str) -> float:
    """``value`` of ``column``, unless beyond what any vehicle does: then a :class:`CueingFileError`
    naming the line, the column and the likely mistake."""
    if column.startswith("f_") and abs(value) > MAX_SPECIFIC_FORCE_M_S2:
        raise CueingFileError(f"{source}: line {line}, column {column}: {value:g} m/s² is beyond "
                              f"±{MAX_SPECIFIC_FORCE_M_S2:g} m/s² (30 g), more than any vehicle a motion platform cues: "
                              "a unit mistake (mm/s²?) or a glitch in the recording; correct or remove the line")
    if column.startswith("omega_") and abs(value) > MAX_ANGULAR_RATE_RAD_S:
        raise CueingFileError(f"{source}: line {line}, column {column}: {value:g} rad/s is beyond "
                              f"±{MAX_ANGULAR_RATE_RAD_S:g} rad/s (2000 deg/s, a gyro's full scale): in deg/s? "
                              "multiply by π/180; else a glitch in the recording: correct or remove the line")
    return value


def _check_gravity(f_z: np.ndarray, source: str) -> None:
    median = float(np.median(f_z))
    low, high = (bound * GRAVITY_M_S2 for bound in F_Z_RANGE_G)
    if not low <= median <= high:
        raise CueingFileError(
            f"{source}: column f_z: {median:g} m/s² (median over the file), where an accelerometer in a vehicle at rest "
            f"reads +{GRAVITY_M_S2:g} m/s²: the specific force is in m/s², gravity included, z up (a file in g: "
            f"multiply f_* by {GRAVITY_M_S2:g}; an acceleration without gravity: add {GRAVITY_M_S2:g} to f_z; "
            "z down, aerospace axes: negate f_y, f_z, omega_y and omega_z)")


def _resolution(written: list[str]) -> float:
    """How finely the times ``written`` (the t_s cells' text, finite numbers) are written,
    s: the place of the last decimal of the one with the most (``0.0167``: 1e-4), so
    every time is rounded (or cut) by less than it. Write every time with as many
    decimals: one written with fewer (``%g``'s ``10.0167`` beside ``0.0166667``) is
    rounded more than this says, and may be taken for unevenness."""
    return float(10.0 ** min(int(Decimal(cell).as_tuple().exponent) for cell in written))


def _uniform_period(times: np.ndarray, resolution_s: float, lines: list[int], source: str) -> float:
    """The sample period (s), from the first time to the last, if the ``times`` (s, each
    rounded to ``resolution_s`` in the text; ``lines``: each one's line in the file)
    increase evenly spaced: :class:`CueingFileError` naming the first line where they do not.

    Evenly spaced times rounded (or cut) to ``resolution_s`` differ from step to step by at
    most one ``resolution_s``, and lie within one of the even spacing from the first to
    the last: a gap or a change of rate breaks the first, a change of rate whose steps each
    look even breaks the second. Both allow :data:`PERIOD_TOLERANCE` more. A gap no longer
    than ``resolution_s`` cannot be told from the rounding."""
    _check_increasing(times, lines, source)
    steps = np.diff(times)
    period = float(times[-1] - times[0]) / len(steps)
    typical = float(np.median(steps))  # the usual step: a gap is one of few, and cannot move it far
    tolerance = resolution_s + PERIOD_TOLERANCE * period
    resample = "samples must be evenly spaced (resample the trajectory at one rate)"
    for step, time, line in zip(steps.tolist(), times[1:].tolist(), lines[1:]):
        if abs(step - typical) > tolerance:
            raise CueingFileError(
                f"{source}: line {line}, column t_s: {time:g} s is {step:g} s after the sample before it, where the "
                f"file's samples are {typical:g} s apart (its median step; times written to {resolution_s:g} s): "
                f"{resample}")
    offsets = times - (times[0] + period * np.arange(len(times)))
    worst = int(np.argmax(np.abs(offsets)))
    if abs(offsets[worst]) > tolerance:
        raise CueingFileError(
            f"{source}: line {lines[worst]}, column t_s: {times[worst]:g} s is {offsets[worst]:+g} s off the file's "
            f"even spacing ({period:g} s, from its first sample to its last; times written to {resolution_s:g} s): "
            f"the rate changes along the file: {resample}")
    return period


def _check_increasing(times: np.ndarray, lines: list[int], source: str) -> None:
    """:class:`CueingFileError` naming the first of the ``times`` (s; ``lines``: each one's
    line) not after the one before it: a repeated or reversed time, before any unevenness,
    which it would otherwise be reported as."""
    for time, before, line in zip(times[1:].tolist(), times.tolist(), lines[1:]):
        if not time > before:
            raise CueingFileError(f"{source}: line {line}, column t_s: {time:g} s is not after the sample before it "
                                  f"({before:g} s): times must increase")
