"""One running service per kept file: the files ``hexactl serve`` keeps for its restart
(the calibration in force, the operator's frames) are each held by the service that
writes them, so that a second service started on them (the same working directory) is
refused instead of overwriting or removing what the first keeps.

The hold is an exclusive ``flock`` on ``.NAME.lock`` beside the kept file (the kept
file itself is replaced at every write); the kernel releases it when its process ends,
however it ends, so a lock file left behind by a killed service never stands in the way.
The holder writes its process id into it, for the refusal's message.
"""

from __future__ import annotations

import fcntl
import logging
import os
from pathlib import Path

log = logging.getLogger(__name__)


class HeldByAnother(Exception):
    """Another process holds the file; the message names the file and that process."""


class Hold:
    """A held file; :meth:`release` (or the kernel, at the process's end) lets it go."""

    def __init__(self, descriptor: int | None) -> None:
        self._descriptor = descriptor

    def release(self) -> None:
        if self._descriptor is not None:
            os.close(self._descriptor)  # the lock goes with its descriptor
            self._descriptor = None


def hold(kept: Path, what: str) -> Hold:
    """Hold ``kept`` (``what`` it keeps, for the message) for this process.

    :raises HeldByAnother: naming ``kept``, ``what``, the holder's process id and what to do
    """
    if kept.is_dir():  # no file to keep there: reading it refuses the start, naming it
        return Hold(None)
    lock = kept.with_name(f".{kept.name}.lock")
    try:
        descriptor = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError as error:
        # Where no lock can be made nothing can be kept either (that is said when it fails).
        log.warning("%s: not held for this service (cannot make %s: %s): another service started on it would not be "
                    "refused", kept, lock, error.strerror)
        return Hold(None)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(descriptor, 32, 0).decode("ascii", "replace").strip()
        os.close(descriptor)
        raise HeldByAnother(
            f"{kept}: another hexactl serve ({f'process {holder}' if holder else 'starting'}) keeps {what} there "
            "for its restart: stop that service first, or run this one in another working directory (or give it "
            "--keep-calibration FILE and --frames FILE of its own)") from None
    os.ftruncate(descriptor, 0)
    os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)
    return Hold(descriptor)
