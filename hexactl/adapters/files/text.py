"""The text of a file an operator hands hexactl (geometry, calibration, sequence, frames,
instrument, measurements, vehicle trajectory, recording, client file): UTF-8.

Editors and spreadsheets on Windows often begin UTF-8 with a byte-order mark: it is
dropped, not read as part of the first key or column name. Text saved as UTF-16 or UTF-32
(Windows' "Unicode"), or in another encoding, is refused naming the file, where, and that
it must be saved as UTF-8.
"""

from __future__ import annotations

import codecs
import errno
import os
from pathlib import Path


class TextFileError(ValueError):
    """A file that cannot be read as text: the message names the file, the problem and what to do."""


_WIDE_MARKS = (codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE, codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)

SAVE_AS_UTF8 = "save it as UTF-8 (the editor's or spreadsheet's encoding setting) and try again"


def decode_text(data: bytes, source: str) -> str:
    """``data`` (the content of ``source``) as text. :class:`TextFileError` unless UTF-8."""
    if data.startswith(_WIDE_MARKS):
        raise TextFileError(f"{source}: UTF-16 or UTF-32 text (it starts with that byte-order mark), not UTF-8: "
                            f"{SAVE_AS_UTF8}")
    if (nul := data.find(b"\0")) >= 0:  # never in a text file hexactl reads; every other byte in UTF-16 text
        raise TextFileError(f"{source}: a NUL byte on line {_line(data, nul)} (UTF-16 text without a byte-order "
                            f"mark, or a damaged file), not UTF-8 text: {SAVE_AS_UTF8}")
    try:
        return data.removeprefix(codecs.BOM_UTF8).decode("utf-8")
    except UnicodeDecodeError as error:
        raise TextFileError(f"{source}: not UTF-8 text (byte 0x{data[error.start]:02x} on line "
                            f"{_line(data, error.start)}): {SAVE_AS_UTF8}") from None


def _line(data: bytes, offset: int) -> int:
    return data.count(b"\n", 0, offset) + 1


def read_problem(error: OSError) -> str:
    """Why ``error`` stopped a read and what to do, for people (``[Errno 21] Is a directory:
    '/tmp'`` says only the first). The one rule for every file hexactl reads."""
    if error.errno == errno.EISDIR:
        return "a folder, not a file: name a file in it"
    if error.errno == errno.ENOENT:
        relative = error.filename is not None and not os.path.isabs(error.filename)
        return "no such file: check the name" + (f" (a relative name is looked up in {os.getcwd()})" if relative else "")
    if error.errno in (errno.EACCES, errno.EPERM):
        return "no permission to read it: check its permissions and its folder's (ls -l)"
    return f"cannot read it: {error.strerror or error}; check the name and the disk"


def read_text(path: str | os.PathLike[str], error: type[Exception] = TextFileError) -> str:
    """The text of the file ``path`` (:func:`decode_text`). Raises ``error`` (the
    reader's own error type, :class:`TextFileError` by default) naming the file when it
    cannot be read (:func:`read_problem`) or is not UTF-8."""
    try:
        data = Path(path).read_bytes()
    except OSError as cause:
        raise error(f"{path}: {read_problem(cause)}") from None
    try:
        return decode_text(data, str(path))
    except TextFileError as cause:
        raise error(str(cause)) from None
