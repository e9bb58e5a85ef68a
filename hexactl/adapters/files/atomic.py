"""Atomic file writes: a reader (or a crash) sees the old file or the new one, never half.

The temporary file is ``.NAME.PID.RANDOM.tmp`` beside the target (``PID``: the writer's
process id, ``RANDOM``: 16 hex digits). A writer killed before its rename cannot remove
it; a later write to the same target does, once it is stale
(:func:`remove_stale_temporaries`).
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import shutil
import stat
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

STALE_AFTER_S = 600.0
"""A temporary left this long (by its modification time) by a process that no longer
runs here is stale. The age protects writers this host cannot see: another machine
sharing the directory, or another PID namespace (a container), whose process id may
be free here. A live writer touches its temporary when it writes it; only the final
fsync and rename follow, well within this."""

_writing: set[str] = set()
"""Names of the temporaries this process is writing now: with its own process id in the
name, the rest are an earlier process's that had the same id (a restarted container's
service is often PID 1 again)."""
_writing_lock = threading.Lock()


def write_atomic(path: str | os.PathLike[str], data: bytes, *, overwrite: bool,
                 before_rename: Callable[[], None] | None = None) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder, fsync and rename,
    after removing stale temporaries of earlier writes to ``path``. ``before_rename`` is
    called once the data are on disk, just before the rename: what must happen for the new
    file to be the one kept (a service taking what it holds); should it raise, nothing is
    renamed, the temporary is removed and its exception propagates.

    With ``overwrite``, a symbolic link is written through (the file it leads to is
    replaced; the link stays a link).

    Raises ``FileExistsError`` when ``path`` exists and ``overwrite`` is false, so nothing
    saved is replaced by accident; :class:`NotARegularFile` when what is there, or what a
    link leads to, is not a regular file (a device, a pipe, a socket, a folder, nothing:
    replaced by a file, ``/dev/null`` was, as root); ``OSError`` when the folder cannot be
    made or the file cannot be written (then the old file is untouched and the temporary
    removed).
    """
    target = Path(path)
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} exists; refusing to overwrite it (use --force)")
    if overwrite:
        target = replaceable(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(target)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.{secrets.token_hex(8)}.tmp")
    with _writing_lock:
        _writing.add(temporary.name)
    try:
        # O_EXCL: never open an existing file or follow a symbolic link; 0o666 minus the
        # umask, as for any saved file.
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            with os.fdopen(descriptor, "wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())
            if before_rename is not None:
                before_rename()
            if overwrite:
                os.replace(temporary, target)
            else:
                _take_new_name(temporary, target)
        except BaseException:
            temporary.unlink(missing_ok=True)
            raise
    finally:
        with _writing_lock:
            _writing.discard(temporary.name)
    directory = os.open(target.parent, os.O_RDONLY)
    try:
        os.fsync(directory)  # make the rename itself durable
    finally:
        os.close(directory)
    return target


class NotARegularFile(OSError):
    """What a write would replace is not a regular file: nothing is written."""


def replaceable(target: Path) -> Path:
    """The file a write with overwrite replaces for ``target``: itself, or the file its
    symbolic link leads to (which stays a link).

    :raises NotARegularFile: there is something else there than a regular file, or a link
        leads to nothing
    """
    if target.is_symlink():
        real = Path(os.path.realpath(target))
        if not real.exists():
            raise NotARegularFile(f"{target} is a symbolic link to {real}, which is not there: nothing is written "
                                  "through it; restore its target, or remove the link")
        target = real
    try:
        mode = target.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):  # nothing there: the write says what it finds on its way
        return target
    if not stat.S_ISREG(mode):
        kind = _KINDS.get(stat.S_IFMT(mode), "not a regular file")
        raise NotARegularFile(f"{target} is {kind}, not a file: refusing to replace it, --force or not; "
                              "write to a file")
    return target


_KINDS = {stat.S_IFDIR: "a folder", stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFIFO: "a named pipe (FIFO)", stat.S_IFSOCK: "a socket"}


def _take_new_name(temporary: Path, target: Path) -> None:
    """Give ``temporary`` the name ``target`` unless something has it: a hard link fails
    on any name in the way (``FileExistsError``), however it got there since the check
    before writing, where a rename would replace it. On a file system without hard links
    (FAT) that check is all there is."""
    try:
        os.link(temporary, target)
    except FileExistsError:
        raise
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.EOPNOTSUPP):
            raise
        if os.path.lexists(target):
            raise FileExistsError(f"{target} exists; refusing to overwrite it (use --force)") from None
        os.replace(temporary, target)
        return
    temporary.unlink()


def keep_aside(path: str | os.PathLike[str]) -> Path:
    """Keep the file at ``path`` under a new name beside it, ``NAME.changed-YYYYmmddTHHMMSS``
    (``-2``, ``-3``… if taken), before it is replaced: a file a service keeps that someone
    changed under it. The one rule for those files; the name is returned, for people.

    :raises OSError: if it cannot be kept (then nothing may replace it)
    """
    source = Path(path)
    stamp = time.strftime("%Y%m%dT%H%M%S")
    for number in range(1, 1000):
        aside = source.with_name(f"{source.name}.changed-{stamp}" + (f"-{number}" if number > 1 else ""))
        try:
            os.link(source, aside)  # the same bytes under a second name, whatever their size
            return aside
        except FileExistsError:
            continue
        except OSError as error:
            if error.errno not in (errno.EPERM, errno.EOPNOTSUPP):
                raise
        try:  # a file system without hard links (FAT): a copy, never over another file
            with open(source, "rb") as original, open(aside, "xb") as copy:
                shutil.copyfileobj(original, copy)
                copy.flush()
                os.fsync(copy.fileno())
            return aside
        except FileExistsError:
            continue
    raise FileExistsError(f"{source}: no free name to keep it aside (remove old {source.name}.changed-* files)")


@contextmanager
def aside_while_replaced(path: str | os.PathLike[str], changed: bool) -> Iterator[Path | None]:
    """Around the replacement of a kept file: where it ``changed`` under its service, it is
    first kept aside (:func:`keep_aside`; its name yielded, else None), and that name is
    removed again if the replacement raises (the changed file is still where it was, its
    only name)."""
    aside = keep_aside(path) if changed else None
    try:
        yield aside
    except BaseException:
        if aside is not None:
            aside.unlink(missing_ok=True)
        raise


def same_file(path: str | os.PathLike[str], other: str | os.PathLike[str]) -> bool:
    """Whether two names lead to one file: resolved alike (relative paths, symbolic links,
    even to a file not there yet), or one file under two hard links. The one rule for an
    output that must not be an input, and for two options that must not share a file."""
    if os.path.realpath(path) == os.path.realpath(other):
        return True
    try:
        return os.path.samefile(path, other)
    except OSError:  # one of them is not there (yet), or unreadable: resolved apart, two files
        return False


def write_problem(error: OSError) -> str:
    """Why ``error`` stopped a write and what to do, for people (a full disk's ``[Errno 28]``
    says neither). The one rule for every file hexactl writes."""
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        advice = "free some space there"
    elif error.errno in (errno.EACCES, errno.EROFS):
        advice = "write where you have permission (and the file system is not read-only)"
    elif error.errno == errno.EPERM:  # what root gets from a file or folder made immutable
        advice = "write where you have permission (a file or folder made immutable refuses even root: lsattr, chattr -i)"
    elif error.errno == errno.ENAMETOOLONG:
        advice = "give a shorter name (at most about 220 bytes: its temporary adds some 30 to it)"
    else:
        advice = "check the folder and the disk"
    return f"{error.strerror or error}; {advice}"


def remove_stale_temporaries(target: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporaries that writers of ``target`` killed before their rename left
    beside it; return those removed.

    Only regular files named exactly as :func:`write_atomic` names them for ``target``
    are considered, and of those only ones older than :data:`STALE_AFTER_S` whose writer
    is gone: its process no longer runs on this host, or the process id is this
    process's and this process is not writing it. A concurrent writer's temporary is
    never touched. A file that cannot be removed (permissions, a race with another cleaner)
    is left; this never fails the write that triggered it.
    """
    target = Path(target)
    # Linux process ids are below 2**22: at most 7 digits.
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(?P<pid>[1-9][0-9]{{0,6}})\.[0-9a-f]{{16}}\.tmp")
    removed: list[Path] = []
    try:
        with os.scandir(target.parent) as listing:
            entries = list(listing)
    except OSError:
        return removed  # a folder we cannot list: write_atomic reports what matters about it
    now, me = time.time(), os.getpid()
    with _writing_lock:  # after listing: a temporary listed while being written is still in the set
        writing = set(_writing)
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if match is None or entry.name in writing:
            continue
        pid = int(match["pid"])
        if pid != me and _running(pid):
            continue
        try:
            if not entry.is_file(follow_symlinks=False) or now - entry.stat(follow_symlinks=False).st_mtime < STALE_AFTER_S:
                continue
            os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists on this host (a zombie counts: it may not be reaped yet)."""
    try:
        os.kill(pid, 0)  # signal 0: existence and permission check only
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True
