"""The data recorder's files: ``NAME.csv``, one row per recorded cycle, and ``NAME.json``.

The CSV's columns are ``t_s`` and ``cycle``, then per signal (in :data:`SIGNALS` order)
its values with the unit in the name: poses ``pose_command_x_mm`` … ``_yaw_deg``, leg
values ``setpoint_1_mm`` … and ``feedback_1_mm`` …, ``lateness_us`` and ``compute_us``.
An empty cell is a value the recorder did not have (no feedback yet, forward kinematics
did not converge). The side file ``NAME.json`` says what was recorded, how it ended and
lists the columns with their units.

A recording is written to ``NAME.csv.partial``, created new (never over a file, no
symbolic link followed) in a directory held open by descriptor, so a directory renamed
meanwhile does not redirect it; :meth:`RecordingFile.finish` moves it to ``NAME.csv``
with a hard link, which fails rather than replace a file made meanwhile. Rows are written
unbuffered, a batch at a time; a batch that cannot be written whole (a full disk) is cut
off again, so the file always ends on a whole row.

:func:`read_recording` and :func:`read_side_file` read them back (``hexactl plot``).
"""

from __future__ import annotations

import csv
import json
import math
import os
from array import array
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexactl.adapters.files.atomic import write_atomic, write_problem
from hexactl.adapters.files.text import SAVE_AS_UTF8, TextFileError, decode_text, read_problem
from hexactl.kinematics.axes import POSE_AXES

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

SIGNALS = ("pose_command", "pose_measured", "setpoints", "feedback", "lateness", "compute")
"""What a recording may hold, in the order of the CSV's columns (after ``t_s`` and ``cycle``)."""


LEADING_COLUMNS = (("t_s", "s"), ("cycle", ""))
"""Every recording's first (column, unit)s: its header starts ``t_s,cycle``."""


def columns(signals: Sequence[str]) -> list[tuple[str, str]]:
    """The CSV's (column, unit) for ``signals``, in file order."""
    pose_units = ["mm"] * 3 + ["deg"] * 3
    out = list(LEADING_COLUMNS)
    for signal in SIGNALS:
        if signal not in signals:
            continue
        if signal in ("pose_command", "pose_measured"):
            out += [(f"{signal}_{axis}_{unit}", unit) for axis, unit in zip(POSE_AXES, pose_units)]
        elif signal == "setpoints":
            out += [(f"setpoint_{leg}_mm", "mm") for leg in range(1, 7)]
        elif signal == "feedback":
            out += [(f"feedback_{leg}_mm", "mm") for leg in range(1, 7)]
        else:
            out.append((f"{signal}_us", "us"))
    return out


@dataclass(frozen=True, slots=True)
class RecordedCycle:
    """One row's values: ``t_s`` since the first row; poses in mm and rad (None: not
    available); set-points and feedback positions in mm (feedback None: none yet);
    lateness and compute in ns."""

    t_s: float
    cycle: int
    pose_command: Sequence[float] | None
    pose_measured: Sequence[float] | None
    setpoints: Sequence[float]
    feedback: Sequence[float] | None
    lateness_ns: int
    compute_ns: int


class RecordingFileError(Exception):
    """A recording's file cannot be made: ``code`` is ``file_exists`` (a file of that name
    is in the way), ``file_not_found`` (the directory cannot be opened) or ``write_failed``
    (the file cannot be created or written: a full disk, permissions)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


class RecordingFile:
    """``NAME.csv.partial`` being written in ``directory``; create with :meth:`create`."""

    def __init__(self, directory: Path, descriptor: int, name: str, signals: Sequence[str], handle: Any) -> None:
        self.directory = directory
        self.path = directory / f"{name}.csv"
        """The CSV's final path."""
        self._descriptor = descriptor
        self._partial = f"{name}.csv.partial"
        self._signals = tuple(signals)
        self._handle = handle
        self._size = 0  # bytes written whole: where a batch that failed is cut off

    @classmethod
    def create(cls, directory: Path, name: str, signals: Sequence[str]) -> RecordingFile:
        """Create ``NAME.csv.partial`` new in ``directory`` (a bare, checked ``name``) and
        write the header. :class:`RecordingFileError` naming the file in the way or the
        directory's problem."""
        try:
            descriptor = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError as error:
            raise RecordingFileError("file_not_found", f"{directory}: cannot open the recordings directory "
                                     f"({error.strerror}): create it or start the service with another --data-dir") from None
        try:
            for existing in (f"{name}.csv", f"{name}.json", f"{name}.csv.partial"):
                if _exists(existing, descriptor):
                    what = ("the rows of a recording the service was stopped in (killed, or its host went down): "
                            "rename it (to a name ending .csv, to plot it) to keep them, or choose another name"
                            if existing.endswith(".partial") else "choose another name or remove that file")
                    raise RecordingFileError("file_exists", f"{directory / existing} exists; a recording never "
                                             f"overwrites a file: {what}")
            handle = os.fdopen(os.open(f"{name}.csv.partial", os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                                       | os.O_APPEND | os.O_CLOEXEC, 0o666, dir_fd=descriptor), "wb", buffering=0)
        except RecordingFileError:
            os.close(descriptor)
            raise
        except OSError as error:
            os.close(descriptor)
            raise RecordingFileError("write_failed", f"{directory / name}.csv.partial: cannot create it: "
                                     f"{write_problem(error)}") from None
        file = cls(directory, descriptor, name, signals, handle)
        try:
            file._write(",".join(column for column, _ in columns(signals)) + "\n")
        except OSError as error:
            file.discard()
            raise RecordingFileError("write_failed", f"{directory / name}.csv.partial: cannot write it: "
                                     f"{write_problem(error)}") from None
        return file

    def append(self, rows: Sequence[RecordedCycle]) -> None:
        """Write ``rows``, all or (OSError) none."""
        signals = self._signals
        lines = []
        for row in rows:
            cells = [f"{row.t_s:.6f}", str(row.cycle)]
            if "pose_command" in signals:
                cells += _pose_cells(row.pose_command)
            if "pose_measured" in signals:
                cells += _pose_cells(row.pose_measured)
            if "setpoints" in signals:
                cells += [f"{value:.6f}" for value in row.setpoints]
            if "feedback" in signals:
                cells += [f"{value:.6f}" for value in row.feedback] if row.feedback is not None else [""] * 6
            if "lateness" in signals:
                cells.append(f"{row.lateness_ns / 1e3:.1f}")
            if "compute" in signals:
                cells.append(f"{row.compute_ns / 1e3:.1f}")
            lines.append(",".join(cells))
        if lines:
            self._write("\n".join(lines) + "\n")

    def _write(self, text: str) -> None:
        """Write ``text`` whole or, cutting off what got written, raise the OSError."""
        encoded = text.encode("utf-8")
        data = memoryview(encoded)
        try:
            while data:  # an unbuffered write may take part of it
                data = data[self._handle.write(data):]
        except OSError:
            try:  # a row cut short would be read as a (wrong) number, or refuse the file
                self._handle.truncate(self._size)
            except OSError:
                pass
            raise
        self._size += len(encoded)

    def discard(self) -> None:
        """Close and remove the partial file (a recording the loop refused)."""
        self._handle.close()
        try:
            os.unlink(self._partial, dir_fd=self._descriptor)
        except OSError:
            pass
        os.close(self._descriptor)

    def finish(self, description: Mapping[str, Any], write_error: OSError | None = None) -> dict[str, Any]:
        """Close the CSV, move it to ``NAME.csv`` (kept under its partial name if a file of
        that name appeared meanwhile, or the file system makes no hard links) and write
        ``NAME.json``: ``description`` with the CSV's path (``csv``) and ``columns``.
        Returns the side file's content, with ``side_file_error`` if it could not be
        written (the CSV stands). After a write that failed (``write_error``, or one here:
        a full disk), or a CSV removed or changed by someone else while it was written, the
        rows are not all in it: it keeps its partial name, and the side file says why
        (``write_error``) and ends ``write_failed``. Renamed by someone else, it holds every
        row: ``csv`` names it where it is now."""
        handle, descriptor = self._handle, self._descriptor
        tampered = None
        where = None  # where the file is now, by its open descriptor: renamed, all its rows are there
        try:
            os.fsync(handle.fileno())
            status = os.fstat(handle.fileno())
        except OSError as error:
            write_error = write_error or error
        else:
            try:
                where = Path(os.readlink(f"/proc/self/fd/{handle.fileno()}"))
            except OSError:
                pass
            if status.st_nlink == 0:
                tampered = "removed while it was being written, and its rows with it"
            elif status.st_size != self._size:
                tampered = (f"changed while it was being written ({status.st_size} bytes in it, {self._size} "
                            "written): rows are missing or not the recorder's")
        try:
            handle.close()
        except OSError:  # unbuffered: nothing left to write; the fsync said whether it all got there
            pass
        path = self.path
        failed = {}
        if write_error is not None or tampered is not None:
            path = self.directory / self._partial
            why = (f"{tampered} (by someone else: the recorder never rewrites its file)" if tampered else
                   f"{write_error.strerror or write_error}: the rows after those in it are not recorded; free some "
                   f"space in {self.directory}")
            failed = {"write_error": f"{path}: {why}", "ended": "write_failed"}
        else:
            try:
                if not _same_file(self._partial, descriptor, status):
                    # Found from outside: renamed, and another file made under its old name, that
                    # one was linked as NAME.csv (no row in it) and said to be the recording.
                    raise FileNotFoundError(self._partial)
                os.link(self._partial, path.name, src_dir_fd=descriptor, dst_dir_fd=descriptor, follow_symlinks=False)
                os.unlink(self._partial, dir_fd=descriptor)
            except FileNotFoundError:  # renamed (its rows all in it), or removed after the check above
                path = self.directory / self._partial
                if where is not None and where.name != self._partial and where.exists():
                    # Found from outside: a .partial renamed by hand was said to be removed "and its rows
                    # with it", though every row was in it under its new name: csv names that.
                    path = where
                else:
                    failed = {"write_error": f"{path}: removed while the recording ended, and its rows with it",
                              "ended": "write_failed"}
            except OSError:  # a file of that name appeared meanwhile, or no hard links here: all the rows, as named
                path = self.directory / self._partial
        side = {**description, "csv": str(path), **failed,
                "columns": [{"name": name, "unit": unit} for name, unit in columns(self._signals)]}
        try:
            # Through the descriptor, like the CSV: into the directory the recording started in.
            write_atomic(Path(f"/proc/self/fd/{descriptor}") / self.path.with_suffix(".json").name,
                         (json.dumps(side, indent=2) + "\n").encode("utf-8"), overwrite=False)
        except OSError as error:
            side["side_file_error"] = f"{self.path.with_suffix('.json')}: not written ({error})"
        finally:
            os.close(descriptor)
        return side


def _pose_cells(pose: Sequence[float] | None) -> list[str]:
    """A pose (mm, rad) as six cells, mm and deg; empty cells without one."""
    if pose is None:
        return [""] * 6
    x, y, z, roll, pitch, yaw = pose
    return [f"{x:.6f}", f"{y:.6f}", f"{z:.6f}", f"{math.degrees(roll):.7f}", f"{math.degrees(pitch):.7f}",
            f"{math.degrees(yaw):.7f}"]


def _same_file(name: str, directory: int, status: os.stat_result) -> bool:
    """Whether ``name`` in ``directory`` is the file of ``status`` (not another made under its name)."""
    try:
        named = os.stat(name, dir_fd=directory, follow_symlinks=False)
    except FileNotFoundError:
        return False
    return (named.st_dev, named.st_ino) == (status.st_dev, status.st_ino)


def _exists(name: str, directory: int) -> bool:
    try:
        os.stat(name, dir_fd=directory, follow_symlinks=False)
    except FileNotFoundError:
        return False
    return True


# -- reading back (hexactl plot) ---------------------------------------------------


class RecordingReadError(ValueError):
    """A recording or its side file cannot be read back: missing, not UTF-8 text, garbled;
    the message names the file, the line where known, and what to do."""


def read_recording(path: Path) -> tuple[list[str], list[NDArray[np.float64]], int | None]:
    """The header, the columns (NaN for an empty cell) and the number of a last line an
    interruption cut, left out (None: none). Read row by row into 8 bytes a value: an hour
    at 500 Hz (1.8 M rows) read whole into Python lists of strings took gigabytes.

    :raises RecordingReadError: a missing, unreadable, not UTF-8 or garbled file, or one
        that is not a recording (no ``t_s`` and ``cycle`` columns) or has no rows
    """
    import numpy as np  # not for every command's start (the CLI imports this module lazily too)

    try:
        with path.open("rb") as raw:
            start = raw.read(1 << 16)
            raw.seek(0, os.SEEK_END)
            if raw.tell():
                raw.seek(-1, os.SEEK_END)
            # Every row the recorder writes ends its line: one that does not was cut (an
            # interrupted recording's .csv.partial), and is left out, not taken for a number.
            cut = raw.read(1) not in (b"\n", b"")
    except FileNotFoundError:
        raise RecordingReadError(f"{path}: no such file (a recording is NAME.csv in the service's data "
                                 "directory)") from None
    except OSError as error:
        raise RecordingReadError(f"{path}: {read_problem(error)}") from None
    try:  # the text files' one rule, on the first lines: UTF-16 and the like named as such
        decode_text(start[:start.rfind(b"\n") + 1] or start, str(path))
    except TextFileError as error:
        raise RecordingReadError(str(error)) from None
    number, cut_line = 1, None
    try:
        with path.open(encoding="utf-8-sig", newline="") as file:
            rows = csv.reader(file)
            header = next(rows, None)
            if header is None:
                raise RecordingReadError(f"{path}: empty: plot a file made by hexactl record")
            if missing := [name for name in ("t_s", "cycle") if name not in header]:
                # Found from outside: a dwell record (t_s, no cycle) was said to have no t_s either
                raise RecordingReadError(f"{path}: not a recording (its header has no {' and no '.join(missing)} "
                                         "column): plot a file made by hexactl record (save-recording writes a "
                                         "sequence's dwell records, which plot does not draw)")
            columns = [array("d") for _ in header]
            held: list[str] | None = None  # the row read last, taken once another follows it (or the file ends whole)
            for number, row in enumerate(rows, start=2):
                if held is not None:
                    _take(held, columns, number - 1, path)
                held = row
            if held is not None and not cut:
                _take(held, columns, number, path)
            elif held is not None:
                cut_line = number
    except UnicodeDecodeError:
        raise RecordingReadError(f"{path}: not UTF-8 text (after line {number}): {SAVE_AS_UTF8}") from None
    except csv.Error as error:  # a NUL byte: not a text file
        raise RecordingReadError(f"{path}: line {number}: {error}: the file is garbled") from None
    except OSError as error:
        raise RecordingReadError(f"{path}: {read_problem(error)}") from None
    if not columns[0]:
        raise RecordingReadError(f"{path}: the recording has no rows")
    return header, [np.frombuffer(column, dtype=np.float64) for column in columns], cut_line


def _take(row: list[str], columns: list[array[float]], number: int, path: Path) -> None:
    """Append line ``number``'s ``row`` to ``columns`` (NaN for an empty cell);
    RecordingReadError when it has another count of values than the header, or one that is
    not a number."""
    if len(row) != len(columns):
        raise RecordingReadError(f"{path}: line {number} has {len(row)} values for {len(columns)} columns: the file "
                                 "is garbled")
    try:
        values = [float(cell) if cell else float("nan") for cell in row]
    except ValueError:
        raise RecordingReadError(f"{path}: line {number} has a value that is not a number: the file is garbled") \
            from None
    for column, value in zip(columns, values):
        column.append(value)


def read_side_file(path: Path) -> dict[str, Any] | None:
    """The side file (``NAME.json``) of the recording at ``path``, None when absent.

    :raises RecordingReadError: it is there but cannot be read
    """
    side = path.with_suffix(".json")
    try:
        return json.loads(side.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise RecordingReadError(f"{side}: the side file cannot be read ({error}): move it away to plot without "
                                 "it") from None
