"""What every sub-command shares: the --config option, pose arguments, error type."""

from __future__ import annotations

import argparse
import re
from math import isfinite

from hexactl.adapters.files.geometry_file import CONFIG_ENVIRONMENT_VARIABLE, default_config_path, load_geometry
from hexactl.kinematics.geometry import Geometry, GeometryError
from hexactl.kinematics.pose import POSE_AXES, validate_pose_values


class CliError(Exception):
    """Bad input to a command: printed as ``hexactl CMD: error: …``, exit status 2."""


def common_parser() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--config",
        metavar="FILE",
        help=f"geometry or calibration TOML (default: ${CONFIG_ENVIRONMENT_VARIABLE}, else config/platform.toml)",
    )
    return common


def load_config(arguments: argparse.Namespace) -> Geometry:
    """The geometry named by --config, or the default one; CliError if it is refused."""
    try:
        return load_geometry(arguments.config or default_config_path())
    except GeometryError as error:
        raise CliError(str(error)) from None


_KEYED = re.compile(r"^\s*(x|y|z|roll|pitch|yaw)\s*=\s*(\S+)\s*$")


def parse_pose_argument(text: str) -> list[float]:
    """A pose typed on the command line, relative to the zero posture (mm, deg).

    Either six comma-separated numbers ``X,Y,Z,ROLL,PITCH,YAW`` or ``axis=value`` pairs
    separated by commas, missing axes 0: ``x=600``, ``pitch=-20,yaw=5``.
    """
    parts = [part for part in text.split(",") if part.strip()]
    if parts and all("=" in part for part in parts):
        pose = [0.0] * 6
        for part in parts:
            match = _KEYED.match(part)
            if not match:
                raise CliError(f"pose {text!r}: {part.strip()!r} is not axis=value with axis one of {', '.join(POSE_AXES)}")
            pose[POSE_AXES.index(match.group(1))] = _number(match.group(2), text)
    else:
        pose = [_number(part, text) for part in parts]
    problem = validate_pose_values(pose)
    if problem:
        raise CliError(f"pose {text!r}: {problem}")
    return pose


def parse_numbers(values: list[str], labels: tuple[str, ...]) -> list[float]:
    """Finite numbers given as separate arguments, one per label (e.g. ``ik X Y Z ROLL PITCH YAW``)."""
    numbers = []
    for label, value in zip(labels, values, strict=True):
        number = _number(value, label)
        if not isfinite(number):
            raise CliError(f"{label}: {value!r} is not a finite number")
        numbers.append(number)
    return numbers


def _number(text: str, context: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise CliError(f"{context}: {text.strip()!r} is not a number") from None
