"""The calibration in force, kept by ``hexactl serve`` across its restarts: a geometry file.

The service's :class:`CalibrationKeeper` follows the calibration the loop has in force
(its snapshot's, not a command's reply): it writes it here whenever it changes (a load,
a rollback, ``--calibration`` at start-up, a swap the loop carried out after the reply
said ``loop_timeout``) and removes the file once the nominal geometry is in force again;
started without ``--calibration``, the service restores what the file holds. The first
line, a comment, says the calibration's id and where it was loaded from, for the log: a
file without it, or holding another calibration, was not left by the service (a copy, an
edit while it was stopped) and is not restored (:class:`KeptCalibrationError`). Written
atomically (whole, old or new, whatever happens during the write).
"""

from __future__ import annotations

import logging
import os
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hexactl.adapters.files.atomic import aside_while_replaced, write_atomic
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.geometry import Geometry, GeometryError

DEFAULT_FILE = "active_calibration.toml"
"""Where the service keeps it, in its working directory, unless set."""

_HEADER = "# the calibration hexactl serve had in force (id {id}), kept for its restart; loaded from {source}"
_HEADER_READ = re.compile(r"# the calibration hexactl serve had in force(?: \(id (?P<id>[0-9a-f]+)\))?, kept for its "
                          r"restart; loaded from (?P<source>.*)")
"""The header as written, and as read: without the id, as services before it wrote it."""


class KeptCalibrationError(ValueError):
    """A kept calibration file the service did not leave as it is: the message says how."""

RETRY_INTERVAL_S = 10.0
"""After a calibration could not be kept, :meth:`CalibrationKeeper.follow` tries it again
once this long at most (not on every telemetry record)."""

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class KeptCalibration:
    """Where a service keeps its calibration in force (``path``), and the id of its nominal
    geometry, which, in force, leaves nothing to keep."""

    path: Path
    nominal_id: str

    def keep(self, geometry: Geometry, calibration_id: str, source: str, kept_before: str | None = None) -> str:
        """Keep ``geometry`` (id ``calibration_id``, loaded from ``source``) as the one in
        force, or remove the kept one if it is the nominal geometry; what was done, for people.
        ``kept_before``: the id of the calibration this service kept there last (None: none
        yet). A file that holds anything else (edited or replaced by hand under the
        service, which reads it at start only) is first kept aside (:func:`aside_while_replaced`).

        :raises OSError: if the file cannot be written or removed, or a changed file cannot
            be kept aside (it is as it was)
        """
        with aside_while_replaced(self.path, kept_before is not None and self._changed(kept_before)) as aside:
            if calibration_id == self.nominal_id:
                forget_calibration(self.path)
                said = "the nominal geometry is in force: no calibration kept for a restart"
            else:
                keep_calibration(geometry, source, self.path)
                said = f"kept for a restart in {self.path}"
        if aside is not None:
            said += (f" ({self.path} had been changed since the service kept calibration {kept_before} in it: that "
                     f"version, never in force, is kept as {aside})")
            log.warning("%s", said)
        return said

    def _changed(self, kept_before: str) -> bool:
        """Whether the file is there and holds another calibration than ``kept_before``."""
        if not os.path.lexists(self.path):
            return False
        try:
            return geometry_id(load_geometry(self.path)) != kept_before
        except GeometryError:
            return True


class CalibrationKeeper:
    """Keeps the calibration in force for a restart: whenever the one ``in_force()`` returns
    (the loop's latest snapshot) is not the one it kept last, :attr:`kept` is written, or
    removed for the nominal geometry. One rule, whatever made the calibration change: a
    load or rollback answered ok, one answered ``loop_timeout`` and carried out a moment
    later, another client of the loop.

    :meth:`follow` is called where the snapshot is looked at regularly (each telemetry
    record); :meth:`keep_now` after a load or rollback, for its reply. Both write from the
    calling thread, never the loop's, and only when the calibration in force has changed
    (a telemetry record that does it is late by the write, once per change). Neither
    raises: a calibration that cannot be kept (``OSError``, or anything else keeping
    raised) is logged as a warning once, and tried again at most every
    ``retry_interval_s`` (``clock``: monotonic s) by :meth:`follow`, at once by
    :meth:`keep_now`; success after it is logged too.
    """

    def __init__(self, kept: KeptCalibration, in_force: Callable[[], ActiveGeometry], *,
                 retry_interval_s: float = RETRY_INTERVAL_S, clock: Callable[[], float] = time.monotonic) -> None:
        self.kept = kept
        self._in_force = in_force
        self._retry_interval_s = retry_interval_s
        self._clock = clock
        self._lock = threading.Lock()  # one keeping at a time: the latest to take it reads what is in force last
        self._kept_id: str | None = None  # the calibration kept last (None: none yet, by this keeper)
        self._said = ""  # what keeping it did, for people
        self._failed: tuple[str, float] | None = None  # the calibration that could not be kept, and when tried

    def follow(self) -> None:
        """Keep the calibration in force if it changed; at once, without waiting for a
        keeping under way in another thread (it reads what is in force itself)."""
        if not self._lock.acquire(blocking=False):
            return
        try:
            active = self._in_force()
            if active.calibration_id == self._kept_id:
                self._failed = None  # one that could not be kept is no longer in force
                return
            if (self._failed is not None and self._failed[0] == active.calibration_id
                    and self._clock() < self._failed[1] + self._retry_interval_s):
                return
            self._keep(active)
        finally:
            self._lock.release()

    def keep_now(self) -> str:
        """Keep the calibration in force if it changed (or could not be kept before); what
        is kept for a restart, or why it is not, for people."""
        with self._lock:
            active = self._in_force()
            if active.calibration_id == self._kept_id:
                self._failed = None
                return self._said
            return self._keep(active)

    def _keep(self, active: ActiveGeometry) -> str:
        calibration_id = active.calibration_id
        try:
            said = self.kept.keep(active.geometry, calibration_id, active.source, self._kept_id)
        except Exception as error:  # OSError (a full disk, permissions); nothing else may stop telemetry either
            said = (f"NOT kept for a restart ({self.kept.path}: {error}): a restart would start on the calibration "
                    "kept before; free the disk or fix the permissions: it is kept as soon as it can be written")
            if self._failed is None or self._failed[0] != calibration_id:
                log.warning("calibration %s %s", calibration_id, said, exc_info=not isinstance(error, OSError))
            self._failed = (calibration_id, self._clock())
            return said
        log.info("calibration %s: %s", calibration_id, said)
        self._kept_id, self._said, self._failed = calibration_id, said, None
        return said


def keep_calibration(geometry: Geometry, source: str, path: str | os.PathLike[str]) -> Path:
    """Write ``geometry``, loaded from ``source``, to ``path``, replacing what was there.

    :raises OSError: if it cannot be written (nothing at ``path`` changed)
    """
    text = _HEADER.format(id=geometry_id(geometry), source=" ".join(source.split())) + "\n" + geometry_to_toml(geometry)
    return write_atomic(path, text.encode("utf-8"), overwrite=True)


def forget_calibration(path: str | os.PathLike[str]) -> None:
    """No calibration kept: the nominal geometry is in force.

    :raises OSError: if the file is there and cannot be removed
    """
    try:
        Path(path).unlink(missing_ok=True)
    except OSError:
        if os.path.lexists(path):  # a read-only file system refuses to remove even what is not there
            raise


def restore_calibration(path: str | os.PathLike[str]) -> tuple[Geometry, str]:
    """The calibration kept in ``path`` and where it was loaded from.

    :raises ~hexactl.kinematics.geometry.GeometryError: naming the file and the problem
    :raises KeptCalibrationError: the file is not as the service left it: no header (a
        calibration copied there, or written by ``calibrate -o``), or another calibration
        than its header's (edited): never loaded through the service, so not restored
    """
    geometry = load_geometry(path)
    with open(path, encoding="utf-8-sig") as file:
        header = _HEADER_READ.fullmatch(file.readline().rstrip("\r\n"))
    if header is None:
        raise KeptCalibrationError(f"{path}: not a calibration the service kept (its first line is not the comment "
                                   "the service writes): a file copied or written there, never loaded through the "
                                   "service")
    if header["id"] is not None and header["id"] != (actual := geometry_id(geometry)):
        raise KeptCalibrationError(f"{path}: holds calibration {actual}, not {header['id']}, the one the service kept "
                                   "there: edited or replaced while the service was stopped")
    return geometry, header["source"]
