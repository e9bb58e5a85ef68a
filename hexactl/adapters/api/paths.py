"""Files a request may name: only files inside the configured data directories.

A request's path is resolved (``..`` and symlinks followed) and refused with
``forbidden_path`` unless the real file lies inside one of the directories, so neither
``../../etc/passwd`` nor a symlink placed in a data directory reaches anything else.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from hexactl.adapters.api.wire import ApiError, ErrorCode

MAX_FILE_BYTES = 4 * 1024 * 1024
"""Largest calibration or sequence file read (a 1000-waypoint sequence is ~100 kB)."""


class DataDirectories:
    """The directories requests may read files from and write recordings to. To read, a
    relative path is looked up in each directory in order, then in the service's
    working directory (so that ``calibrations/x.toml`` means what it says where the
    service was started); wherever it is found, the file must lie inside one of the
    directories."""

    def __init__(self, directories: Sequence[str | os.PathLike[str]]) -> None:
        self.directories = tuple(Path(directory).resolve() for directory in directories)

    def resolve(self, text: str) -> Path:
        """The real path of the file ``text`` names. :class:`ApiError` ``forbidden_path``
        if it is outside every data directory, ``file_not_found`` if it is inside but
        is not a regular file."""
        self._check_text(text)
        path = Path(text)
        candidates = [path] if path.is_absolute() else [*(directory / path for directory in self.directories), Path.cwd() / path]
        inside = None
        for candidate in candidates:
            real = candidate.resolve()
            if not any(real.is_relative_to(directory) for directory in self.directories):
                continue
            if os.path.isfile(real):  # False, not OSError, for a name too long
                return real
            inside = inside or real
        if inside is None:
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: outside the data directories", self._listing())
        raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: no such file in the data directories")

    def new_file(self, text: str) -> Path:
        """Where to create the file ``text`` names: relative to the first data directory,
        or absolute; :class:`ApiError` ``forbidden_path`` unless its real directory is
        inside a data directory, ``file_not_found`` if that directory does not exist."""
        self._check_text(text)
        path = Path(text) if Path(text).is_absolute() else self.directories[0] / text
        if path.name in ("", ".", ".."):
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: not a file name")
        parent = path.parent.resolve()
        if not any(parent.is_relative_to(directory) for directory in self.directories):
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: outside the data directories", self._listing())
        if not os.path.isdir(parent):  # False, not OSError, for a name too long
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: no such directory in the data directories")
        return parent / path.name

    def read_text(self, text: str, invalid: ErrorCode) -> tuple[Path, str]:
        """(real path, UTF-8 content) of the file ``text`` names, after :meth:`resolve`;
        ``too_large`` above :data:`MAX_FILE_BYTES`, ``invalid`` if it is not UTF-8."""
        path = self.resolve(text)
        try:
            with path.open("rb") as handle:
                data = handle.read(MAX_FILE_BYTES + 1)
        except OSError as error:
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot read: {error.strerror}") from None
        if len(data) > MAX_FILE_BYTES:
            raise ApiError(ErrorCode.TOO_LARGE, f"{text}: larger than {MAX_FILE_BYTES} bytes")
        try:
            return path, data.decode("utf-8")
        except UnicodeDecodeError:
            raise ApiError(invalid, f"{text}: not UTF-8 text") from None

    def _listing(self) -> dict[str, list[str]]:
        return {"data_directories": [str(directory) for directory in self.directories]}

    @staticmethod
    def _check_text(text: str) -> None:
        if not text or "\0" in text:
            raise ApiError(ErrorCode.FORBIDDEN_PATH, "a path is a non-empty string without NUL characters")
