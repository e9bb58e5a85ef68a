"""The calibration in force, kept by ``hexactl serve`` across its restarts: a geometry file.

The service writes the active calibration here whenever it changes (a load, a rollback,
``--calibration`` at start-up) and removes the file once the nominal geometry is in force
again; started without ``--calibration``, it restores what the file holds. The first line,
a comment, says where the calibration was loaded from, for the log. Written atomically
(whole, old or new, whatever happens during the write).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from hexactl.adapters.files.atomic import write_atomic
from hexactl.adapters.files.geometry_file import geometry_to_toml, load_geometry
from hexactl.kinematics.geometry import Geometry

DEFAULT_FILE = "active_calibration.toml"
"""Where the service keeps it, in its working directory, unless set."""

_FROM = "# the calibration hexactl serve had in force, kept for its restart; loaded from "


@dataclass(frozen=True, slots=True)
class KeptCalibration:
    """Where a service keeps its calibration in force (``path``), and the id of its nominal
    geometry, which, in force, leaves nothing to keep."""

    path: Path
    nominal_id: str

    def keep(self, geometry: Geometry, calibration_id: str, source: str) -> str:
        """Keep ``geometry`` (id ``calibration_id``, loaded from ``source``) as the one in
        force, or remove the kept one if it is the nominal geometry; what was done, for people.

        :raises OSError: if the file cannot be written or removed (it is as it was)
        """
        if calibration_id == self.nominal_id:
            forget_calibration(self.path)
            return "the nominal geometry is in force: no calibration kept for a restart"
        keep_calibration(geometry, source, self.path)
        return f"kept for a restart in {self.path}"


def keep_calibration(geometry: Geometry, source: str, path: str | os.PathLike[str]) -> Path:
    """Write ``geometry``, loaded from ``source``, to ``path``, replacing what was there.

    :raises OSError: if it cannot be written (nothing at ``path`` changed)
    """
    text = _FROM + " ".join(source.split()) + "\n" + geometry_to_toml(geometry)
    return write_atomic(path, text.encode("utf-8"), overwrite=True)


def forget_calibration(path: str | os.PathLike[str]) -> None:
    """No calibration kept: the nominal geometry is in force.

    :raises OSError: if the file is there and cannot be removed
    """
    Path(path).unlink(missing_ok=True)


def restore_calibration(path: str | os.PathLike[str]) -> tuple[Geometry, str]:
    """The calibration kept in ``path`` and where it was loaded from (``path`` itself if
    the file does not say).

    :raises ~hexactl.kinematics.geometry.GeometryError: naming the file and the problem
    """
    geometry = load_geometry(path)
    with open(path, encoding="utf-8") as file:
        first = file.readline().rstrip("\n")
    return geometry, first[len(_FROM):] if first.startswith(_FROM) else str(path)
