"""What every sub-command shares: the --config option, pose arguments, error type; how a
campaign-driving command (``demo``, ``campaign``) ends when stopped."""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from math import isfinite
from pathlib import Path
from typing import TYPE_CHECKING

from hexactl.adapters.files.geometry_file import CONFIG_ENVIRONMENT_VARIABLE, default_config_path, load_geometry
from hexactl.kinematics.geometry import Geometry, GeometryError
from hexactl.kinematics.pose import POSE_AXES, validate_pose_values

if TYPE_CHECKING:  # the campaign's modules load only when a command drives one
    from hexactl.adapters.campaign.driver import CampaignError
    from hexactl.adapters.campaign.progress import Progress


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


def check_campaign_arguments(arguments: argparse.Namespace) -> None:
    """``--per-leg`` and ``--envelope`` of a campaign-driving command (``demo``, ``campaign``).

    :raises CliError: naming the option and what it must be
    """
    if arguments.per_leg < 1:
        raise CliError(f"--per-leg {arguments.per_leg}: at least one posture per leg")
    if not 0 < arguments.envelope <= 1:
        raise CliError(f"--envelope {arguments.envelope}: a fraction in (0, 1]")


def campaign_stopped(command: str, stopped_by: CampaignError | KeyboardInterrupt, directory: Path, progress: Progress,
                     on_interrupt: Callable[[], None] | None = None) -> int:
    """The exit status of ``hexactl COMMAND`` driving a campaign in ``directory`` when
    ``stopped_by`` ended it: the progress line finished, then the reason on stderr. A
    :class:`~hexactl.adapters.campaign.driver.CampaignError` (it cannot go on): 1. Ctrl-C:
    ``on_interrupt`` runs, then how to resume (everything measured is saved): 130."""
    progress.finish()
    if isinstance(stopped_by, KeyboardInterrupt):
        if on_interrupt is not None:
            on_interrupt()
        print(f"hexactl {command}: interrupted; what was measured is saved in {directory}: run the same command to "
              "resume", file=sys.stderr)
        return 130
    print(f"hexactl {command}: {stopped_by}", file=sys.stderr)
    return 1


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
