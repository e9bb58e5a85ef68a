"""Where a campaign's measurements come from (``--instrument``):

* ``sim``: the service's simulated instrument (the API's ``measure``), which sees the
  simulator's true platform;
* ``csv:FILE``: a file of measured feature points that a real instrument (laser tracker,
  theodolite software) writes, row k being the campaign's k-th measurement; the campaign
  waits for a row that is not there yet;
* ``prompt``: typed at the terminal, point by point.

Each measurement is the geometry's feature points, in their order, as [x, y, z] in the
fixed (instrument) frame, mm.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.files.measurements import (
    MeasurementFileError,
    PointRows,
    parse_point_rows,
)
from hexactl.adapters.files.text import read_text
from hexactl.calibration.data import MeasurementData, screen_measurements
from hexactl.kinematics.geometry import Geometry

CSV_POLL_S = 0.5
"""How often a campaign waiting for an instrument file's next row looks again."""


class InstrumentError(Exception):
    """The instrument cannot deliver a measurement; the message says why."""


class Instrument(Protocol):
    """Measures the platform's feature points: measurement number ``index`` (0-based,
    counting every measurement of the campaign in order), described to people by ``label``."""

    description: str

    def measure(self, index: int, label: str) -> NDArray[np.float64]:
        """(K, 3) feature points, fixed frame, mm; raises :class:`InstrumentError`."""
        ...


class ServiceInstrument:
    """The service's simulated instrument, through the API's ``measure``."""

    description = "the service's simulated instrument"

    def __init__(self, client: HexactlClient) -> None:
        self.client = client

    def measure(self, index: int, label: str) -> NDArray[np.float64]:
        try:
            return np.array(self.client.call("measure")["points"], dtype=float)
        except CommandError as error:
            if error.code == "no_instrument":
                raise InstrumentError(f"measure: {error} (use --instrument csv:FILE or prompt with real actuators)") from None
            raise InstrumentError(f"measure: {error}: nothing was measured at {label}; run the same command again to "
                                  "resume") from None


class CsvInstrument:
    """Row ``index`` of the instrument file ``path`` (comments and blank lines do not
    count). The file is checked whole when opened and again whenever it is read: a bad
    row refuses it, naming every bad line. ``say`` tells the operator when the campaign
    waits for a row.

    A row is a new measurement only if it was written after :meth:`measure` was called,
    which the campaign does once the platform is at rest at the posture: a row there
    before was measured while the platform moved, or for a measurement the campaign did
    not keep (a fault or a move interrupted it; the file was opened with it), and is
    refused, never taken for this posture."""

    def __init__(self, path: Path, feature_point_count: int, say: Callable[[str], None] = print) -> None:
        self.path = Path(path)
        self.description = f"the instrument file {self.path}"
        self._feature_point_count = feature_point_count
        self._say = say
        self._rows()  # checked whole now, before anything moves
        self._taken = 0  # rows no measurement may be: there before it was asked for, or read already

    def _rows(self) -> PointRows:
        text = read_text(self.path, InstrumentError)
        try:
            rows = parse_point_rows(text, str(self.path), self._feature_point_count)
        except MeasurementFileError as error:
            raise InstrumentError(str(error)) from None
        if rows.problems:
            raise InstrumentError("\n".join(f"{self.path}: {problem}" for problem in rows.problems))
        return rows

    def measure(self, index: int, label: str) -> NDArray[np.float64]:
        waiting = False
        while True:
            rows = self._rows()
            # Rows deleted since: the rows that take their place are new. On the first look,
            # every row there is old: written before the platform was at rest here.
            self._taken = len(rows.lines) if not waiting else min(self._taken, len(rows.lines))
            if index < self._taken:
                raise InstrumentError(
                    f"{self.path}: rows {index + 1}-{len(rows.lines)} (lines {rows.lines[index]}-{rows.lines[-1]}) were "
                    f"there before the platform was at rest at {label}: the campaign kept {index} measurements, so these were "
                    "measured while it moved there, or for postures or waypoints it did not keep (a fault, a stop or "
                    f"an interruption came first), or for another campaign; delete them from {self.path} and run the same command again: it "
                    f"waits for row {index + 1} and measures it anew")
            if index < len(rows.lines):
                self._taken = index + 1
                return np.array(rows.points_mm[index])
            if not waiting:
                self._say(f"waiting for row {index + 1} of {self.path} ({label}): measure now")
                waiting = True
            time.sleep(CSV_POLL_S)


class PromptInstrument:
    """The operator types each feature point's x y z (mm, fixed frame; spaces or commas).
    A point that is not three numbers is asked again; a measurement that the measurement
    files' screening would flag (points collinear, or inter-point distances off the known
    ones: a mis-sighted target or a typo) is asked again whole."""

    description = "measurements typed at the terminal"

    def __init__(self, geometry: Geometry, ask: Callable[[str], str] = input, say: Callable[[str], None] = print) -> None:
        self.model = np.array(geometry.measurement.feature_points, dtype=float)
        self.point_sigma_mm = geometry.measurement.point_sigma_mm
        self._ask = ask
        self._say = say

    def measure(self, index: int, label: str) -> NDArray[np.float64]:
        self._say(f"measure {label}: type each feature point's x y z in mm (fixed frame)")
        while True:
            points = np.array([self._point(k) for k in range(1, len(self.model) + 1)])
            problems = self._problems(points)
            if not problems:
                return points
            self._say("; ".join(problems) + ": measure again")

    def _point(self, number: int) -> list[float]:
        while True:
            try:
                answer = self._ask(f"  p{number} x y z: ")
            except EOFError:
                raise InstrumentError("the terminal closed before the measurement was typed") from None
            fields = [field for field in re.split(r"[\s,;]+", answer.strip()) if field]
            try:
                values = [float(field) for field in fields]
            except ValueError:
                values = []
            if len(values) == 3 and all(np.isfinite(values)):
                return values
            self._say(f"  {answer.strip()!r} is not three numbers x y z")

    def _problems(self, points: NDArray) -> list[str]:
        """What the measurement files' screening would say of ``points`` (collinear, or
        inter-point distances off the known ones)."""
        row = MeasurementData(np.zeros(1, dtype=np.int64), np.zeros((1, 6)), np.zeros(1, dtype=np.int64),
                              points_mm=points[None])
        return [str(problem) for problem in screen_measurements(row, self.model, self.point_sigma_mm)]


def open_instrument(spec: str, client: HexactlClient, geometry: Geometry, say: Callable[[str], None] = print) -> Instrument:
    """The instrument ``spec`` names: ``sim``, ``csv:FILE`` or ``prompt``. Raises
    ``ValueError`` for another spec and :class:`InstrumentError` for an unusable file."""
    if spec == "sim":
        return ServiceInstrument(client)
    if spec == "prompt":
        return PromptInstrument(geometry, say=say)
    if spec.startswith("csv:") and len(spec) > len("csv:"):
        return CsvInstrument(Path(spec[len("csv:"):]), len(geometry.measurement.feature_points), say)
    raise ValueError(f"--instrument {spec!r}: use sim, csv:FILE or prompt")
