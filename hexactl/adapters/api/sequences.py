"""What ``play`` plays: a built-in sequence, a sequence file, a posture plan, or inline
waypoints, as the control layer's :class:`~hexactl.control.sequences.MotionSequence`.

Files are read and validated here, in the API thread, never in the control loop; their
formats are :mod:`hexactl.adapters.files.sequence_file`'s: a ``.toml`` sequence file, or
a ``.csv`` plan as ``hexactl plan-leglock`` writes it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hexactl.adapters.api.messages import InlineSequence
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError, ErrorCode, problems_error
from hexactl.adapters.files.sequence_file import sequence_from_plan, sequence_from_toml
from hexactl.control.sequences import (
    BUILTIN_SEQUENCES,
    MotionSequence,
    SequenceError,
    UnknownSequence,
    builtin_sequence,
    sequence_from_mapping,
)

SEQUENCE_READERS: dict[str, Callable[[str, str], MotionSequence]] = {
    ".toml": sequence_from_toml, ".csv": sequence_from_plan,
}
"""A file's reader by how its name ends (in any case); any other name is a built-in's."""


def resolve_sequence(sequence: str | InlineSequence, data: DataDirectories) -> MotionSequence:
    """The sequence a ``play`` request names. :class:`ApiError` ``unknown_sequence`` for a
    name that is neither built in nor a ``.toml`` or ``.csv`` file, the path errors of
    :meth:`DataDirectories.read_text`, ``invalid_sequence`` for a refused sequence."""
    try:
        if isinstance(sequence, InlineSequence):
            document = sequence.model_dump(exclude={"waypoints"})
            document["waypoint"] = [waypoint.model_dump() for waypoint in sequence.waypoints]  # the file's key
            return sequence_from_mapping(document, "sequence")
        # by how the name ends, not by PurePath's suffix: ".toml" alone is a name without one
        reader = next((read for ending, read in SEQUENCE_READERS.items() if sequence.lower().endswith(ending)), None)
        if reader is None:
            return builtin_sequence(sequence)
        path, text = data.read_text(sequence, ErrorCode.INVALID_SEQUENCE)
        return reader(text, str(path))
    except UnknownSequence as error:
        assert isinstance(sequence, str)  # an inline sequence is no name
        if Path(sequence).name != sequence:  # a path: neither ending, so never a file to play
            raise ApiError(ErrorCode.UNKNOWN_SEQUENCE, f"{sequence!r}: a path, but a sequence file's name ends in "
                           ".toml and a posture plan's in .csv (a directory or another file cannot be played)",
                           {"built_in": list(BUILTIN_SEQUENCES)}) from None
        if (file := _file_named(sequence, data)) is not None:
            raise ApiError(ErrorCode.UNKNOWN_SEQUENCE, f"{error}; but {file} is a sequence file there: play {file.name} "
                           "(a file is named with its ending)", {"built_in": list(BUILTIN_SEQUENCES),
                                                                 "file": str(file)}) from None
        raise ApiError(ErrorCode.UNKNOWN_SEQUENCE, f"{error}; or name a .toml sequence file or a .csv plan "
                       "(from hexactl plan-leglock) in a data directory", {"built_in": list(BUILTIN_SEQUENCES)}) from None
    except SequenceError as error:
        raise problems_error(ErrorCode.INVALID_SEQUENCE, str(error)) from None


def _file_named(name: str, data: DataDirectories) -> Path | None:
    """The sequence file or plan directly in a data directory that ``name`` names but for
    its ending (``xy_square`` for ``xy_square.toml``), if there is one; None for a name
    with a directory in it."""
    if Path(name).name != name or name.startswith("."):
        return None
    for directory in data.directories:
        for ending in SEQUENCE_READERS:
            if (candidate := Path(directory) / f"{name}{ending}").is_file():
                return candidate
    return None
