"""Files a request may name: only files inside the configured data directories.

A request's path is resolved (``..`` and symlinks followed) and refused with
``forbidden_path`` unless the real file lies inside one of the directories, so neither
``../../etc/passwd`` nor a symlink placed in a data directory reaches anything else.

Anyone who can write into a data directory can change it between that check and the
open, so the check is not trusted alone: the resolved path is opened one component at a
time from the data directory without following any symlink (a symlink or a special file
swapped in fails the open instead of being followed), non-blocking (a FIFO opens without
waiting for a writer), and the open descriptor decides: a regular file, of bounded size,
whose real path (``/proc/self/fd``, Linux) lies inside a data directory. Nothing swapped
into a data directory can block the API thread or make it read or write outside them.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePath

from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.adapters.files.atomic import write_atomic, write_problem
from hexactl.adapters.files.recording_file import LEADING_COLUMNS
from hexactl.adapters.files.text import TextFileError, decode_text
from hexactl.kinematics.axes import POSE_AXES

MAX_FILE_BYTES = 4 * 1024 * 1024
"""Largest calibration or sequence file read (a 1000-waypoint sequence is ~100 kB)."""

_DIRECTORY_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
_FILE_FLAGS = os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_NOCTTY | os.O_CLOEXEC
_READ_CHUNK_BYTES = 64 * 1024
_CSV_HEAD_BYTES = 64 * 1024  # a plan's comments and header fit many times over

SECRET_KEY_SUFFIX = ".key_secret"
"""A CURVE secret key's file (``hexactl keys``): never served, wherever it lies."""

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


class DataDirectories:
    """The directories requests may read files from and write recordings to. To read, a
    relative path is looked up in each directory in order, then in the service's
    working directory (so that ``calibrations/x.toml`` means what it says where the
    service was started); the first place where it opens as a regular file inside one of
    the directories is read."""

    def __init__(self, directories: Sequence[str | os.PathLike[str]]) -> None:
        self.directories = tuple(Path(directory).resolve() for directory in directories)

    def read_text(self, text: str, invalid: ErrorCode) -> tuple[Path, str]:
        """(real path, UTF-8 content) of the file ``text`` names. :class:`ApiError`
        ``forbidden_path`` if it is outside every data directory; ``file_not_found`` if it
        is inside but missing, not a regular file, unreadable, or changed while being
        opened; ``too_large`` above :data:`MAX_FILE_BYTES`; ``invalid`` if not UTF-8."""
        opened, descriptor, size_bytes = self._open(text)
        try:
            data = _read_bounded(text, descriptor, size_bytes)
        finally:
            os.close(descriptor)
        try:
            return opened, decode_text(data, text)
        except TextFileError as error:
            raise ApiError(invalid, str(error)) from None

    def read_chunk(self, text: str, offset: int, length: int) -> tuple[Path, bytes, int]:
        """(real path, at most ``length`` bytes from ``offset``, the file's size) of the file
        ``text`` names, found and checked as :meth:`read_text` does, of any size: a long
        recording is read a chunk per request."""
        opened, descriptor, size_bytes = self._open(text)
        try:
            # Beyond the end there is nothing to read: pread refuses offsets from 2**63 - 1 on.
            return opened, os.pread(descriptor, length, offset) if offset < size_bytes else b"", size_bytes
        except OSError as error:
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot read: {error.strerror}") from None
        finally:
            os.close(descriptor)

    def files(self, limit: int) -> list[dict[str, object]]:
        """The regular files directly in each data directory (symlinks not followed), at
        most ``limit``: ``name``, ``directory``, ``kind`` (:func:`toml_kind`, :func:`csv_kind`), ``size``
        (bytes) and ``modified`` (s since the epoch)."""
        found: list[dict[str, object]] = []
        for directory in self.directories:
            try:
                entries = sorted(os.scandir(directory), key=lambda entry: entry.name)
            except OSError:
                continue  # a data directory removed since start-up lists nothing
            for entry in entries:
                if len(found) >= limit:
                    return found
                if _private(entry.name):
                    continue
                try:
                    if not entry.is_file(follow_symlinks=False):
                        continue
                    status = entry.stat(follow_symlinks=False)
                except OSError:
                    continue
                found.append({"name": entry.name, "directory": str(directory), "kind": self._kind_of(entry),
                              "size": status.st_size, "modified": status.st_mtime})
        return found

    def _kind_of(self, entry: os.DirEntry[str]) -> str:
        suffix = Path(entry.name).suffix.lower()
        try:
            if suffix == ".toml":
                return toml_kind(self.read_text(entry.path, ErrorCode.FILE_NOT_FOUND)[1])
            if suffix == ".csv":  # its header tells, and a recording may be large: its head only
                return csv_kind(self.read_chunk(entry.path, 0, _CSV_HEAD_BYTES)[1].decode("utf-8", errors="replace"))
        except ApiError:
            pass
        return "other"

    def _open(self, text: str) -> tuple[Path, int, int]:
        """(real path, open descriptor, size) of the regular file ``text`` names inside a
        data directory; the caller closes the descriptor. Refusals as :meth:`read_text`'s."""
        self._check_text(text)
        path = Path(text)
        candidates = [path] if path.is_absolute() else [*(directory / path for directory in self.directories), Path.cwd() / path]
        problem: ApiError | None = None  # the first found inside that is not a readable file
        missing = False
        escaping: Path | None = None  # the first that is there, a link to outside the directories
        for candidate in candidates:
            try:
                real = candidate.resolve()
            except (OSError, RuntimeError):  # a loop, or a symlink replaced as it was read (EINVAL)
                problem = problem or _unresolvable(text)
                continue
            directory = self._containing(real)
            if directory is None:
                inside_by_name = self._containing(Path(os.path.abspath(candidate))) is not None
                if escaping is None and inside_by_name and os.path.lexists(candidate):
                    escaping = candidate
                continue
            try:
                descriptor = _open_file_beneath(directory, real.relative_to(directory))
            except FileNotFoundError:
                missing = True
                continue
            except OSError as error:
                problem = problem or _open_refusal(text, error)
                continue
            try:
                status = os.fstat(descriptor)
                if kind := _kind(status.st_mode):
                    problem = problem or ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: not a regular file ({kind}); name a file")
                    os.close(descriptor)
                    continue
                return self._place(text, descriptor), descriptor, status.st_size
            except BaseException:
                os.close(descriptor)
                raise
        if problem is not None:
            raise problem
        if escaping is not None:  # "no such file" of a file the operator sees there misleads
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: {escaping} leads outside the data directories (a "
                           "symbolic link): copy the file into one instead", self._listing())
        if missing:
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: no such file in the data directories", self._listing())
        raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: outside the data directories", self._listing())

    def write_new(self, text: str, data: bytes, reserved: Mapping[Path, str] | None = None) -> Path:
        """Write ``data`` to a new file ``text`` names (relative to the first data directory,
        or absolute) atomically; its real path. :class:`ApiError` ``forbidden_path`` unless
        its directory is inside a data directory, ``file_not_found`` if that directory does
        not exist, ``write_failed`` if the file cannot be written, ``file_exists`` if the file
        exists or is one of ``reserved`` (real paths, each with why: a file being written)."""
        self._check_text(text)
        path = Path(text) if Path(text).is_absolute() else self.directories[0] / text
        if path.name in ("", ".", ".."):
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: not a file name")
        if _private(path.name):
            raise _private_refusal(text)
        try:
            parent = path.parent.resolve()
        except (OSError, RuntimeError):
            raise _unresolvable(text) from None
        directory = self._containing(parent)
        if directory is None:
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: outside the data directories", self._listing())
        try:
            descriptor = _open_directory_beneath(directory, parent.relative_to(directory))
        except OSError as error:
            raise _open_refusal(text, error) from None
        try:
            real_parent = self._place(text, descriptor)
            if why := (reserved or {}).get(real_parent / path.name):
                raise ApiError(ErrorCode.FILE_EXISTS, f"{text}: {why}: choose another name")
            # Through the descriptor's own /proc entry, every step of the write happens in
            # the directory just checked, whatever is renamed onto its path meanwhile.
            write_atomic(Path(f"/proc/self/fd/{descriptor}") / path.name, data, overwrite=False)
        except FileExistsError:
            if (Path(f"/proc/self/fd/{descriptor}") / path.name).is_dir():
                raise ApiError(ErrorCode.FILE_EXISTS, f"{text}: is a directory: name a file") from None
            raise ApiError(ErrorCode.FILE_EXISTS, f"{text}: exists; a saved file is never overwritten: choose another name") from None
        except OSError as error:
            raise ApiError(ErrorCode.WRITE_FAILED, f"{text}: cannot write: {write_problem(error)}") from None
        finally:
            os.close(descriptor)
        return real_parent / path.name

    def _containing(self, real: Path) -> Path | None:
        return next((directory for directory in self.directories if real.is_relative_to(directory)), None)

    def _place(self, text: str, descriptor: int) -> Path:
        """The real path of what ``descriptor`` opened: the check no rename can race.
        :class:`ApiError` ``forbidden_path`` unless it is inside a data directory."""
        try:
            real = Path(os.readlink(f"/proc/self/fd/{descriptor}"))
        except OSError as error:
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot tell where the opened file lies "
                           f"(/proc/self/fd: {error.strerror}); mount /proc") from None
        directory = self._containing(real)
        if directory is None:
            raise ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: outside the data directories", self._listing())
        if any(_private(part) for part in real.relative_to(directory).parts):
            raise _private_refusal(text)
        return real

    def _listing(self) -> dict[str, list[str]]:
        return {"data_directories": [str(directory) for directory in self.directories]}

    @staticmethod
    def _check_text(text: str) -> None:
        if not text or "\0" in text:
            raise ApiError(ErrorCode.FORBIDDEN_PATH, "a path is a non-empty string without NUL characters")
        if text.rsplit("/", 1)[-1] in ("", "."):  # pathlib would drop it and name the file before it
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: ends as a directory's name does ('/' or '/.'); "
                           "name a file")


def _private(name: str) -> bool:
    """Whether a file or directory of this name is never served or written: hidden (a
    data directory may be an operator's home, the configuration's: ``.ssh``, ``.netrc``)
    or a secret key (the keys kept beside the configuration)."""
    return name.startswith(".") or name.endswith(SECRET_KEY_SUFFIX)


def _private_refusal(text: str) -> ApiError:
    return ApiError(ErrorCode.FORBIDDEN_PATH, f"{text}: hidden files and directories (names starting with '.') and "
                    f"secret keys (*{SECRET_KEY_SUFFIX}) are never read or written by requests; name another file")


def _open_directory_beneath(directory: Path, relative: PurePath) -> int:
    """A descriptor of the directory ``directory/relative``, opened from ``directory`` one
    component at a time without following a symlink: ``relative`` is already resolved, so
    a symlink met is one swapped in since (``OSError`` ENOTDIR), never a way out."""
    descriptor = os.open(directory, _DIRECTORY_FLAGS)
    for part in relative.parts:
        try:
            child = os.open(part, _DIRECTORY_FLAGS, dir_fd=descriptor)
        finally:
            os.close(descriptor)
        descriptor = child
    return descriptor


def _open_file_beneath(directory: Path, relative: PurePath) -> int:
    """A descriptor of the file ``directory/relative`` (resolved), opened as
    :func:`_open_directory_beneath` opens its directory, without blocking and without
    following a final symlink (``OSError`` ELOOP)."""
    parent = _open_directory_beneath(directory, relative.parent)
    try:
        return os.open(relative.name, _FILE_FLAGS, dir_fd=parent)
    finally:
        os.close(parent)


def _read_bounded(text: str, descriptor: int, size_bytes: int) -> bytes:
    """The content of the regular file of ``size_bytes`` (by fstat); :class:`ApiError`
    ``too_large`` above :data:`MAX_FILE_BYTES`, also if it grows past it while read."""
    if size_bytes > MAX_FILE_BYTES:
        raise _too_large(text)
    chunks, size = [], 0
    try:
        while chunk := os.read(descriptor, _READ_CHUNK_BYTES):
            chunks.append(chunk)
            size += len(chunk)
            if size > MAX_FILE_BYTES:
                raise _too_large(text)
    except OSError as error:
        raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot read: {error.strerror}") from None
    return b"".join(chunks)


def toml_kind(toml_text: str) -> str:
    """What a TOML file in a data directory holds, by its keys: ``calibration`` (a
    geometry: it has ``base_joints``), ``sequence`` (``[[waypoint]]``) or ``other``."""
    lines = {line.split("=", 1)[0].strip() for line in toml_text.splitlines()}
    if "base_joints" in lines:
        return "calibration"
    if "[[waypoint]]" in lines:
        return "sequence"
    return "other"


def csv_kind(head: str) -> str:
    """What a CSV file in a data directory holds, by its header (its first line that is
    not blank or a ``#`` comment): ``recording`` (``t_s,cycle,…``, the data recorder's),
    ``sequence`` (a posture plan's ``leg`` and pose columns: ``play`` takes it) or
    ``other`` (a measurement file, anything else)."""
    header = next((line for line in head.splitlines() if line.strip() and not line.lstrip().startswith("#")), "")
    names = [name.strip() for name in header.split(",")]
    if names[:len(LEADING_COLUMNS)] == [column for column, _ in LEADING_COLUMNS]:
        return "recording"
    if {"leg", *POSE_AXES} <= set(names):
        return "sequence"
    return "other"


def _kind(mode: int) -> str | None:
    """What a file that is not a regular file is (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def _open_refusal(text: str, error: OSError) -> ApiError:
    if error.errno == errno.ENOENT:
        return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: no such directory in the data directories")
    if error.errno == errno.ELOOP:  # a symlink where the resolved path has none: swapped in since
        return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: changed while being opened (a symlink swapped in); "
                        "try again")
    if error.errno == errno.ENOTDIR:  # a file, or a symlink not followed (O_NOFOLLOW), where a directory was
        return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: a part of the path is not a directory (a file, or a "
                        "symlink swapped in while being opened)")
    if error.errno == errno.ENXIO:  # a socket
        return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: not a regular file (a socket); name a file")
    return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot open: {error.strerror}")


def _unresolvable(text: str) -> ApiError:
    return ApiError(ErrorCode.FILE_NOT_FOUND, f"{text}: cannot be resolved (a symlink loop, or it changed while "
                    "being resolved); name a file")


def _too_large(text: str) -> ApiError:
    return ApiError(ErrorCode.TOO_LARGE, f"{text}: larger than {MAX_FILE_BYTES} bytes")
