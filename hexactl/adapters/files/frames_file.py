"""The operator's frames file (TOML, mm and degrees): where the service keeps the work and
tool frames and the soft limits across restarts.

```toml
work = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]     # the work frame in the zero frame
tool = [0.0, 0.0, 300.0, 0.0, 0.0, 0.0]   # the tool frame (origin: the pivot point) in the platform's frame

[soft_limits]
max_tilt_deg = 5.0

[soft_limits.lower]                        # per axis; an axis not named has no bound
x = -50.0

[soft_limits.upper]
x = 50.0
```

TOML has no null, so a bound that is not set is a key left out. Written atomically (the
file is whole, old or new, whatever happens during the write).
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Callable
from pathlib import Path

import tomli_w
from pydantic import ValidationError

from hexactl.adapters.files.atomic import aside_while_replaced, write_atomic
from hexactl.adapters.files.geometry_file import toml_value
from hexactl.adapters.files.text import read_text
from hexactl.control.frames import OperatorFrames
from hexactl.kinematics.axes import POSE_AXES
from hexactl.kinematics.validation_messages import describe_validation_error


class FramesFileError(ValueError):
    """A frames file that cannot be used; the message names the file, key and problem."""


def load_frames(path: str | os.PathLike[str]) -> OperatorFrames:
    """The frames in ``path``.

    :raises FramesFileError: unreadable, not TOML, empty, or a value refused (each named)
    """
    location = Path(path)
    text = read_text(location, FramesFileError)
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as error:
        raise FramesFileError(f"{location}: not valid TOML: {error}") from None
    if not data:  # a saved file always holds work and tool: an empty one lost what it held
        raise FramesFileError(f"{location}: empty (no work, tool or soft_limits): the file lost its content, and "
                              "with it perhaps the operator's soft limits")
    limits = data.get("soft_limits")
    tables = []
    if isinstance(limits, dict):
        for side in ("lower", "upper"):
            if isinstance(bounds := limits.get(side), dict):
                unknown = sorted(set(bounds) - set(POSE_AXES))
                if unknown:
                    raise FramesFileError(f"{location}: soft_limits.{side}: unknown axis {', '.join(unknown)}; the "
                                          f"axes are {', '.join(POSE_AXES)}")
                limits[side] = [bounds.get(axis) for axis in POSE_AXES]
                tables.append(side)
    try:
        return OperatorFrames.model_validate(data)
    except ValidationError as error:
        # A bound is named as written, [soft_limits.upper] yaw = …, not by its place in the list.
        raise FramesFileError(describe_validation_error(
            error, str(location), {f"soft_limits.{side}": POSE_AXES for side in tables}, OperatorFrames)) from None


def frames_to_toml(frames: OperatorFrames) -> str:
    """The TOML text of ``frames``; round-trips through :func:`load_frames`."""
    limits = frames.soft_limits
    lines = ["# hexactl operator frames: mm and degrees (docs/api.md, Frames)",
             f"work = {toml_value(list(frames.work))}", f"tool = {toml_value(list(frames.tool))}"]
    soft: dict[str, object] = {}
    if limits.max_tilt_deg is not None:
        soft["max_tilt_deg"] = limits.max_tilt_deg
    for side, bounds in (("lower", limits.lower), ("upper", limits.upper)):
        named = {axis: bound for axis, bound in zip(POSE_AXES, bounds) if bound is not None}
        if named:
            soft[side] = named
    text = "\n".join(lines) + "\n"
    return text + "\n" + tomli_w.dumps({"soft_limits": soft}) if soft else text


def save_frames(frames: OperatorFrames, path: str | os.PathLike[str], in_force: OperatorFrames,
                before_rename: Callable[[], None] | None = None) -> Path | None:
    """Write ``frames`` to ``path`` atomically, replacing the frames ``in_force`` until now;
    ``before_rename`` once they are on disk, before they replace the file
    (:func:`write_atomic`). A file that holds anything else (edited by hand under the
    service, which reads it at start only) is first kept aside (:func:`aside_while_replaced`);
    its new name is returned (None: there was nothing to keep).

    :raises OSError: if it cannot be written, or the changed file cannot be kept aside
        (then nothing at ``path`` changed)
    """
    with aside_while_replaced(path, os.path.lexists(path) and file_differs(path, in_force) is not None) as aside:
        write_atomic(path, frames_to_toml(frames).encode("utf-8"), overwrite=True, before_rename=before_rename)
    return aside


def file_differs(path: str | os.PathLike[str], in_force: OperatorFrames) -> str | None:
    """Why the file at ``path`` does not hold the frames ``in_force`` (None: it does): it was
    edited or removed since the service read it at start or last wrote it."""
    location = Path(path)
    if not os.path.lexists(location):
        return None if in_force == OperatorFrames() else "it was removed"
    try:
        held = load_frames(location)
    except FramesFileError as error:
        return f"it cannot be used now ({error})"
    return None if held == in_force else "it was changed: it holds other frames than those in force"
