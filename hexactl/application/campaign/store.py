"""A campaign's directory: its plan and every measurement, saved as they are taken.

Files (all written atomically: a crash leaves the previous version or the new one):

* ``campaign.json``: the plan, written once: the geometry it was planned on (name and
  content id), the design (postures per leg, candidates, envelope fraction, seed) and the
  postures in visiting order (locked leg, relative pose in mm and deg);
* ``measurements.csv``: one row per measured posture, the measurement-file format of
  ``hexactl calibrate`` (locked leg, six readings, the feature points), rewritten after
  every posture;
* ``validation.csv``: the test motions measured before and after calibration, one row
  per waypoint (``phase``, ``motion``, ``waypoint`` 1-based, the commanded pose
  ``command_*``, the achieved pose ``achieved_*`` computed from the points, both relative
  mm/deg, and the feature points ``p1_x`` …), rewritten after every waypoint; its first
  line, a comment, ends with ``measured with: before=ID after=ID``, the calibration the
  controller ran for each phase's rows (one per phase: the runner never mixes them);
* ``calibration.toml`` and ``report/`` at the end;
* ``campaign.lock``, locked while a campaign runs there: a second one is refused.

Measurements are taken in one order: the waypoints before calibration, the postures,
the waypoints after. So the saved rows say exactly where an interrupted campaign
resumes, and how many measurements an instrument file must already hold.
"""

from __future__ import annotations

import csv
import fcntl
import io
import json
import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from hexactl.application.campaign.driver import CampaignError
from hexactl.adapters.files.atomic import write_atomic, write_problem
from hexactl.adapters.files.geometry_file import geometry_id
from hexactl.adapters.files.measurements import (
    MeasurementFile,
    MeasurementFileError,
    read_measurements,
    write_measurements,
)
from hexactl.adapters.report.html import REPORT_PAGE
from hexactl.calibration.campaign import (
    CampaignDesign,
    CampaignPosture,
    achieved_pose,
    campaign_postures,
    plan_campaign,
)
from hexactl.calibration.data import MeasurementData
from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS, TestMotion
from hexactl.calibration.validation import MotionResult
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.axes import POSE_AXES

PLAN_FILE = "campaign.json"
MEASUREMENTS_FILE = "measurements.csv"
VALIDATION_FILE = "validation.csv"
CALIBRATION_FILE = "calibration.toml"
REPORT_DIRECTORY = "report"
LOCK_FILE = "campaign.lock"
PHASES = ("before", "after")
"""Validation phases: on the planning geometry, then with the calibration loaded."""

_FORMAT = "hexactl campaign 1"
_MEASURED_WITH = "measured with:"
_DECIMALS = 6  # mm: what the measurement files keep (a nanometre)


class DirectoryError(CampaignError):
    """The directory cannot hold this campaign (finished, another plan, foreign files)."""


@dataclass(frozen=True, slots=True)
class ValidationStep:
    """A waypoint to measure: ``phase``, ``motion``, ``waypoint`` (1-based), ``pose`` relative mm/deg."""

    phase: str
    motion: TestMotion
    waypoint: int
    pose: tuple[float, ...]


VALIDATION_STEPS: dict[str, tuple[ValidationStep, ...]] = {
    phase: tuple(ValidationStep(phase, motion, number, tuple(pose))
                 for motion in PAPER_TEST_MOTIONS for number, pose in enumerate(motion.waypoints, start=1))
    for phase in PHASES
}
"""The paper's test motions, waypoint by waypoint, for each phase."""


@dataclass(frozen=True, slots=True)
class _ValidationRow:
    step: ValidationStep
    points_mm: NDArray[np.float64]
    calibration_id: str | None
    """The calibration the controller ran while it was measured; None: not recorded (a
    file of an older hexactl)."""


class CampaignStore:
    """The directory of one campaign; :meth:`open` creates or resumes it."""

    def __init__(self, directory: Path, geometry: Geometry, design: CampaignDesign,
                 postures: tuple[CampaignPosture, ...]) -> None:
        self.directory = directory
        self.geometry = geometry
        self.design = design
        self.postures = postures
        """The postures in visiting order."""
        self._legs: list[int] = []
        self._readings: list[NDArray] = []
        self._points: list[NDArray] = []
        self._validation: list[_ValidationRow] = []
        self._lock: TextIO | None = None  # held while open: two campaigns must not share a directory

    # -- opening -----------------------------------------------------------------------

    @classmethod
    def open(cls, directory: Path, geometry: Geometry, design: CampaignDesign) -> CampaignStore:
        """Resume the campaign in ``directory``, or plan a new one there on ``geometry``
        (the controller's) and save the plan.

        Raises :class:`DirectoryError` if the directory holds a finished campaign, one
        planned on another geometry or with another design, or files that are not a
        campaign's; :class:`CampaignError` if planning fails or saved files are damaged.
        """
        directory = Path(directory)
        ensure_unfinished(directory)
        lock = _lock(directory)
        try:
            plan_path = directory / PLAN_FILE
            if plan_path.exists():
                store = cls._resumed(directory, geometry, design)
            else:
                strays = [name for name in (MEASUREMENTS_FILE, VALIDATION_FILE, CALIBRATION_FILE)
                          if (directory / name).exists()]
                if strays:
                    raise DirectoryError(f"{directory} holds {', '.join(strays)} but no {PLAN_FILE}: not a campaign's "
                                         "directory; choose another --out")
                try:
                    plans = plan_campaign(geometry, design)
                except ValueError as error:
                    raise CampaignError(f"planning: {error}") from None
                store = cls(directory, geometry, design, campaign_postures(plans, geometry.characteristic_length_mm))
                with saving(plan_path):
                    write_atomic(plan_path, store._plan_json().encode("utf-8"), overwrite=False)
        except BaseException:
            lock.close()
            raise
        store._lock = lock
        return store

    def close(self) -> None:
        """Let another campaign open the directory."""
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __enter__(self) -> CampaignStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @classmethod
    def _resumed(cls, directory: Path, geometry: Geometry, design: CampaignDesign) -> CampaignStore:
        path = directory / PLAN_FILE
        try:
            saved = json.loads(path.read_text(encoding="utf-8"))
            if saved.get("format") != _FORMAT:
                raise ValueError(f"format {saved.get('format')!r}, expected {_FORMAT!r}")
            postures = tuple(CampaignPosture(int(item["leg"]), tuple(float(v) for v in item["pose"]))  # type: ignore[arg-type]
                             for item in saved["postures"])
            planned_on, saved_design = saved["geometry"], saved["design"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise CampaignError(f"{path}: not a campaign plan: {error}") from None
        if planned_on["id"] != geometry_id(geometry):
            raise DirectoryError(f"{directory} holds a campaign planned on geometry {planned_on['name']!r} "
                                f"({planned_on['id']}), not this one ({geometry_id(geometry)}): give that geometry "
                                "(--config) or choose another --out")
        if saved_design != _design_fields(design):
            raise DirectoryError(f"{directory} holds a campaign planned with {saved_design}; this one asks for "
                                f"{_design_fields(design)}: resume with those options or choose another --out")
        store = cls(directory, geometry, design, postures)
        store._load_measurements()
        store._load_validation()
        return store

    def _load_measurements(self) -> None:
        path = self.directory / MEASUREMENTS_FILE
        if not path.exists():
            return
        try:
            saved = read_measurements(path, len(self.geometry.measurement.feature_points))
        except MeasurementFileError as error:
            raise CampaignError(str(error)) from None
        data = saved.data
        planned = [posture.leg for posture in self.postures[: len(data)]]
        if saved.problems or data.points_mm is None or len(data) > len(self.postures) or list(data.locked_leg) != planned:
            raise CampaignError(f"{path} does not match {PLAN_FILE} (edited by hand?): move it away to measure "
                                "those postures again, or choose another --out")
        self._legs = [int(leg) for leg in data.locked_leg]
        self._readings = list(data.readings_mm)
        self._points = list(data.points_mm)

    def _load_validation(self) -> None:
        path = self.directory / VALIDATION_FILE
        if not path.exists():
            return
        expected = [step for phase in PHASES for step in VALIDATION_STEPS[phase]]
        count = len(self.geometry.measurement.feature_points)
        columns = [f"p{k}_{axis}" for k in range(1, count + 1) for axis in "xyz"]
        planned = geometry_id(self.geometry)
        try:
            # A file of an older hexactl names no calibration. Its rows before calibration were
            # measured on the planned geometry (campaign.json pins it, and every waypoint was
            # checked against it); its rows after calibration cannot be attributed to a
            # calibration, and an accuracy verdict on unattributed data is worthless: they are
            # measured again (the runner says so), which costs minutes, not the campaign.
            text = path.read_text(encoding="utf-8")
            named = dict(re.findall(r"\b(before|after)=([0-9a-f]+)", text.partition("\n")[0].partition(_MEASURED_WITH)[2]))
            header: list[str] | None = None
            for line in text.splitlines():
                if not line or line.startswith("#"):
                    continue
                if header is None:
                    header = next(csv.reader([line]))
                    continue
                row = dict(zip(header, next(csv.reader([line]))))
                step = expected[len(self._validation)]
                if (row["phase"], row["motion"], int(row["waypoint"])) != (step.phase, step.motion.name, step.waypoint):
                    raise ValueError(f"expected {step.phase} {step.motion.name} waypoint {step.waypoint}")
                points = np.array([float(row[name]) for name in columns]).reshape(count, 3)
                self._validation.append(_ValidationRow(step, points, named.get(step.phase) or
                                                       (planned if step.phase == "before" else None)))
        except (OSError, ValueError, KeyError, IndexError) as error:
            raise CampaignError(f"{path} does not match the test motions (edited by hand?): {error}") from None

    # -- progress ----------------------------------------------------------------------

    @property
    def measurements_taken(self) -> int:
        """Every measurement saved so far: the index of the next one."""
        return len(self._validation) + len(self._legs)

    @property
    def postures_measured(self) -> int:
        return len(self._legs)

    def validation_steps_left(self, phase: str) -> tuple[ValidationStep, ...]:
        done = sum(1 for row in self._validation if row.step.phase == phase)
        return VALIDATION_STEPS[phase][done:]

    # -- saving ------------------------------------------------------------------------

    def add_posture(self, leg: int, readings_mm: Sequence[float], points_mm: NDArray) -> None:
        """Save the next posture's measurement (its leg must be the plan's)."""
        expected = self.postures[len(self._legs)].leg
        if leg != expected:
            raise ValueError(f"posture {len(self._legs) + 1} locks leg {expected}, not {leg}")
        self._legs.append(leg)
        self._readings.append(np.array(readings_mm, dtype=float))
        self._points.append(np.array(points_mm, dtype=float))
        comments = [f"hexactl campaign: {len(self._legs)} of {len(self.postures)} postures of {PLAN_FILE}, "
                    f"geometry {self.geometry.name!r}"]
        path = self.directory / MEASUREMENTS_FILE
        with saving(path):
            write_measurements(path, self.measurements(), overwrite=True, comments=comments)

    def add_validation(self, step: ValidationStep, points_mm: NDArray, calibration_id: str | None = None) -> None:
        """Save the next waypoint's measurement (``step`` must be the next one), taken with
        calibration ``calibration_id`` active (before calibration: the planned geometry's,
        the default)."""
        if step not in self.validation_steps_left(step.phase)[:1]:
            raise ValueError(f"{step.phase} {step.motion.name} waypoint {step.waypoint} is not the next to measure")
        if calibration_id is None:
            if step.phase != "before":
                raise ValueError(f"a waypoint {step.phase} calibration needs the calibration it was measured with")
            calibration_id = geometry_id(self.geometry)
        # Rounded as the file keeps them, so that a resumed campaign computes what an uninterrupted one does.
        self._validation.append(_ValidationRow(step, np.round(np.array(points_mm, dtype=float), _DECIMALS),
                                               calibration_id))
        self._save_validation()

    def discard_after(self, calibration_id: str | None) -> tuple[str | None, ...]:
        """Forget the waypoints after calibration not measured with ``calibration_id``
        (None: all of them), so that they are measured again; returns the calibration ids
        they were measured with (None: not recorded)."""
        stale = [row for row in self._validation if row.step.phase == "after" and row.calibration_id != calibration_id]
        if stale:
            self._validation = [row for row in self._validation if row not in stale]
            self._save_validation()
        return tuple(row.calibration_id for row in stale)

    def _save_validation(self) -> None:
        path = self.directory / VALIDATION_FILE
        with saving(path):
            write_atomic(path, self._validation_csv().encode("utf-8"), overwrite=True)

    # -- reading -----------------------------------------------------------------------

    def measurements(self) -> MeasurementData:
        """The postures measured so far, lines numbered 1… in measuring order (as saved:
        :meth:`measurement_file` reads the file itself)."""
        count = len(self._legs)
        return MeasurementData(np.array(self._legs, dtype=np.int64), np.array(self._readings).reshape(count, 6),
                               np.arange(1, count + 1), points_mm=np.array(self._points).reshape(count, -1, 3))

    def validation_results(self, phase: str) -> tuple[MotionResult, ...]:
        """Each test motion's achieved poses in ``phase`` (all its waypoints measured)."""
        if self.validation_steps_left(phase):
            raise ValueError(f"the {phase} validation is not complete")
        rows = [row for row in self._validation if row.step.phase == phase]
        return tuple(MotionResult(motion, np.array([achieved_pose(self.geometry, row.points_mm)
                                                    for row in rows if row.step.motion is motion]))
                     for motion in PAPER_TEST_MOTIONS)

    def measurement_file(self) -> MeasurementFile:
        """``measurements.csv`` read back: what identification uses, with the file's hash."""
        return read_measurements(self.directory / MEASUREMENTS_FILE, len(self.geometry.measurement.feature_points))

    def path(self, name: str) -> Path:
        return self.directory / name

    # -- formats -----------------------------------------------------------------------

    def _plan_json(self) -> str:
        document = {
            "format": _FORMAT,
            "geometry": {"name": self.geometry.name, "id": geometry_id(self.geometry)},
            "design": _design_fields(self.design),
            "postures": [{"leg": posture.leg, "pose": list(posture.pose)} for posture in self.postures],
        }
        return json.dumps(document, indent=1) + "\n"

    def _validation_csv(self) -> str:
        count = len(self.geometry.measurement.feature_points)
        out = io.StringIO()
        phases = {phase: {row.calibration_id for row in self._validation if row.step.phase == phase} for phase in PHASES}
        if any(len(ids) > 1 for ids in phases.values()):
            raise ValueError(f"the test motions of one phase measured with several calibrations: {phases}")
        # In the comment, not a column: readers of the columns by position keep working.
        named = " ".join(f"{phase}={next(iter(ids))}" for phase, ids in phases.items() if ids and None not in ids)
        out.write("# hexactl campaign: the paper's test motions measured before and after calibration; "
                  f"poses relative to the zero posture (mm, deg), points in the fixed frame (mm); {_MEASURED_WITH} {named}\n")
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["phase", "motion", "waypoint", *(f"command_{a}" for a in POSE_AXES),
                         *(f"achieved_{a}" for a in POSE_AXES), *(f"p{k}_{a}" for k in range(1, count + 1) for a in "xyz")])
        for row in self._validation:
            step = row.step
            achieved = achieved_pose(self.geometry, row.points_mm)
            writer.writerow([step.phase, step.motion.name, step.waypoint, *(f"{v:.{_DECIMALS}f}" for v in step.pose),
                             *(f"{v:.{_DECIMALS}f}" for v in achieved),
                             *(f"{v:.{_DECIMALS}f}" for v in row.points_mm.ravel())])
        return out.getvalue()


@contextmanager
def saving(path: Path) -> Iterator[None]:
    """Writing ``path``: an ``OSError`` (the directory made read-only or immutable, a full
    disk) becomes a :class:`CampaignError` naming the file and what to do."""
    try:
        yield
    except OSError as error:
        raise CampaignError(f"cannot write {path}: {write_problem(error)}. What was saved before is kept; once "
                            f"{path.parent} can be written, run the same command again to resume (a measurement not "
                            "saved is taken again)") from None


def make_directory(directory: Path) -> None:
    """``directory`` and its missing parents; :class:`DirectoryError` naming why it cannot be made."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise DirectoryError(f"cannot make the directory {directory}: {error.strerror or error}") from None


def _lock(directory: Path) -> TextIO:
    """The directory's lock file, locked (released when closed or when the process ends);
    :class:`DirectoryError` if another campaign holds it."""
    make_directory(directory)
    handle = (directory / LOCK_FILE).open("a", encoding="utf-8")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        raise DirectoryError(f"{directory} is in use by another campaign running now") from None
    return handle


def ensure_unfinished(directory: Path) -> None:
    """:class:`DirectoryError` if ``directory`` holds a finished campaign (its report)."""
    if (directory / REPORT_DIRECTORY / REPORT_PAGE).exists():
        raise DirectoryError(f"{directory} holds a finished campaign ({REPORT_DIRECTORY}/{REPORT_PAGE}): choose another --out")


def _design_fields(design: CampaignDesign) -> dict[str, float]:
    """The parts of a design that decide the plan."""
    return {"postures_per_leg": design.postures_per_leg, "candidates": design.candidates,
            "envelope_fraction": design.envelope_fraction, "seed": design.seed}
