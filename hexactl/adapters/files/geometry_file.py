"""Geometry and calibration files (TOML, mm and degrees): reading, writing, finding.

The format is documented in config/platform.toml and README.md. A calibration file is a
geometry file with identified values and a ``[calibration]`` table.
"""

from __future__ import annotations

import hashlib
import json
import os
import tomllib
from pathlib import Path

import tomli_w

from firmware_proto.codec import STROKE_MAX_UM, STROKE_MIN_UM, VELOCITY_MAX_UM_S
from hexactl.adapters.files.atomic import write_atomic
from hexactl.adapters.files.text import read_text
from hexactl.calibration.parameters import covariance_problem
from hexactl.kinematics.geometry import Geometry, GeometryError, Limits, geometry_from_mapping

_UM_PER_MM = 1000.0


def parse_geometry(text: str, source: str) -> Geometry:
    """Validate TOML text into a :class:`Geometry`; :class:`GeometryError` names every problem.

    Besides the geometry's own rules, checked here where every geometry and calibration
    file is read (a load, a rollback, the service's start): the actuators' limits and a
    calibration's covariance against its own standard deviations
    (:func:`~hexactl.calibration.parameters.covariance_problem`)."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as error:  # RecursionError: arrays nested 1000 deep
        raise GeometryError(f"{source}: not valid TOML: {error}") from None
    if not data:  # else every key "Field required": the file's emptiness said nowhere
        raise GeometryError(f"{source}: empty (no key at all{': being written?' if not text.strip() else ''}): a "
                            "geometry or calibration file names base_joints, platform_joints, zero_lengths, home, "
                            "limits and measurement")
    geometry = geometry_from_mapping(data, source)
    problems = _actuator_problems(geometry.limits)
    if geometry.calibration is not None and (problem := covariance_problem(geometry.calibration)):
        problems.append(f"calibration.{problem}")
    if problems:
        raise GeometryError("\n".join(f"{source}: {problem}" for problem in problems))
    return geometry


def _actuator_problems(limits: Limits) -> list[str]:
    """The ``[limits]`` the actuators cannot follow, one sentence each naming the key.

    Checked here, where every geometry and calibration file is read (the kinematics know
    no wire): with a stroke beyond the actuators' (or beyond what the CAN set-point field
    carries, far wider) the loop plans a move, starts it and then has its set-points
    refused mid-motion (FAULT, every leg held where it was).
    """
    problems = []
    low, high = limits.stroke
    if not STROKE_MIN_UM <= low * _UM_PER_MM <= high * _UM_PER_MM <= STROKE_MAX_UM:
        problems.append(
            f"limits.stroke: {list(limits.stroke)} mm reaches beyond the actuators' stroke, "
            f"{STROKE_MIN_UM / _UM_PER_MM:g} to {STROKE_MAX_UM / _UM_PER_MM:g} mm (firmware_proto/PROTOCOL.md sections "
            "1 and 4): they would refuse the set-points beyond it mid-motion; it is in mm (not µm): give the actuators' "
            "soft limits")
    if limits.leg_velocity_mm_s * _UM_PER_MM > VELOCITY_MAX_UM_S:
        problems.append(
            f"limits.leg_velocity_mm_s: {limits.leg_velocity_mm_s:g} mm/s is beyond the speeds the actuators' feedback "
            f"carries ({VELOCITY_MAX_UM_S / _UM_PER_MM:g} mm/s, firmware_proto/PROTOCOL.md section 3): it is in mm/s "
            "(not mm/min); give the actuators' real speed limit")
    return problems


def load_geometry(path: str | os.PathLike[str]) -> Geometry:
    """Read a geometry or calibration file; :class:`GeometryError` names the file, key and problem."""
    return parse_geometry(read_text(path, GeometryError), str(path))


def geometry_to_toml(geometry: Geometry) -> str:
    """The TOML text of ``geometry``, one joint per line; round-trips through :func:`parse_geometry`.

    Written here rather than with a generic TOML writer because those put every number of
    a nested array on its own line, which makes a geometry file unreadable for a person.
    """
    document = _document(geometry, exclude_none=True)
    tables = {key: value for key, value in document.items() if isinstance(value, dict)}
    lines = [_toml_assignment(key, value) for key, value in document.items() if key not in tables]
    for table, content in tables.items():
        lines += ["", f"[{table}]"] + [_toml_assignment(key, value) for key, value in content.items()]
    return "\n".join(lines) + "\n"


def _toml_assignment(key: str, value: object) -> str:
    if isinstance(value, list) and value and isinstance(value[0], list):
        rows = "".join(f"    {toml_value(row)},\n" for row in value)
        return f"{key} = [\n{rows}]"
    return f"{key} = {toml_value(value)}"


def toml_value(value: object) -> str:
    """``value`` (a string, bool, number or list of them) as TOML, a list on one line."""
    if isinstance(value, (str, bool, int, float)):
        return tomli_w.dumps({"v": value})[len("v = ") : -1]
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to a geometry file")


def save_geometry(geometry: Geometry, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write ``geometry`` atomically; refuses to replace an existing file unless ``overwrite``."""
    return write_atomic(path, geometry_to_toml(geometry).encode("utf-8"), overwrite=overwrite)


def geometry_id(geometry: Geometry) -> str:
    """Content hash identifying a geometry: 16 hex digits of the SHA-256 of its validated
    values (keys sorted, numbers in their shortest exact form, -0.0 as 0.0), so equal
    values get equal ids whatever the file's comments, layout, key order or number
    spelling (``1750`` or ``1750.0``)."""
    canonical = json.dumps(_canonical(_document(geometry)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()[:16]


_ADDED_LATER = (("sensor_scale_errors",), ("measurement", "feature_point_sigma_mm"))
"""Keys added to the format after files were written: left out at their default."""


def _document(geometry: Geometry, exclude_none: bool = False) -> dict:
    """``geometry``'s values for a file or a hash. Keys added to the format later are left
    out at their defaults (exact sensors, exactly known feature points), so such files and
    ids stay what they were, and campaigns that name a geometry by its id keep finding it."""
    document = geometry.model_dump(mode="json", exclude_none=exclude_none)
    for path in _ADDED_LATER:
        table, model = document, geometry
        for key in path[:-1]:
            table, model = table[key], getattr(model, key)
        field = type(model).model_fields[path[-1]]
        if getattr(model, path[-1]) == field.get_default(call_default_factory=True):
            del table[path[-1]]
    return document


def _canonical(value: object) -> object:
    """``value`` with every float zero made +0.0 (equal values, different JSON otherwise)."""
    if isinstance(value, dict):
        return {key: _canonical(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_canonical(item) for item in value]
    if isinstance(value, float) and value == 0.0:
        return 0.0
    return value
