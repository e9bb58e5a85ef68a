"""Measured postures: the identification's input, and the checks that guard it.

One posture is one row of a measurement file: which leg was locked (1–6, 0 for none), the
six sensor readings, and the measured posture, either as an absolute pose or as the
fixed-frame coordinates of the feature points (the raw instrument output). Every posture
keeps the line it came from so that any problem can be reported where the user can fix it.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from itertools import combinations, permutations

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.inverse import LEG_COUNT, LegModel, lengths_from_readings, sensor_setpoints_batch
from hexactl.kinematics.points import DegeneratePointsError, pose_from_points
from hexactl.kinematics.rotation import rotation_matrices

DISTANCE_TOLERANCE_SIGMAS = 5.0
"""Default inter-point distance tolerance, in standard deviations of a measured distance."""

LOCKED_READING_TOLERANCE_MM = 0.1
"""Default: a locked leg whose reading moves more than this from its group's median was not locked."""

SCALE_TOLERANCE = 2.0
"""Measured points spread more than this factor above or below the feature points are in another unit."""


@dataclass(frozen=True, slots=True)
class RowProblem:
    """Something wrong with one row: ``line`` is the 1-based line in the source (0: none).
    ``mis_sighting``: a feature point that disagrees with the others, which an estimator
    that tests each observation (``full``) can exclude itself."""

    line: int
    message: str
    mis_sighting: bool = False

    def __str__(self) -> str:
        return f"line {self.line}: {self.message}" if self.line else self.message


@dataclass(frozen=True, slots=True, eq=False)
class MeasurementData:
    """N measured postures.

    ``locked_leg`` (N,) int, 1–6 or 0; ``readings_mm`` (N, 6) sensor readings; exactly one of
    ``poses`` (N, 6) absolute (mm, rad) or ``points_mm`` (N, K, 3) feature points in the
    fixed frame, point k being the geometry's ``feature_points[k]``; ``lines`` (N,) source
    lines; ``point_covariance_mm2`` (N, K, 3, 3): each point's covariance when an
    instrument's own observations were turned into it (:mod:`hexactl.calibration.observations`;
    None: isotropic, the geometry's ``point_sigma_mm``). Arrays are copied read-only.
    """

    locked_leg: NDArray[np.int64]
    readings_mm: NDArray[np.float64]
    lines: NDArray[np.int64]
    poses: NDArray[np.float64] | None = None
    points_mm: NDArray[np.float64] | None = None
    point_covariance_mm2: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if (self.poses is None) == (self.points_mm is None):
            raise ValueError("give either measured poses or measured points")
        count = len(np.asarray(self.locked_leg))
        points_shape = None if self.points_mm is None else np.shape(self.points_mm)
        shapes = {
            "locked_leg": (np.int64, (count,)),
            "readings_mm": (float, (count, LEG_COUNT)),
            "lines": (np.int64, (count,)),
            "poses": (float, (count, 6)),
            "points_mm": (float, (count, points_shape[1], 3) if points_shape and len(points_shape) == 3 else None),
            "point_covariance_mm2": (float, (count, points_shape[1], 3, 3) if points_shape and len(points_shape) == 3
                                     else None),
        }
        for name, (dtype, shape) in shapes.items():
            value = getattr(self, name)
            if value is None:
                continue
            array = np.array(value, dtype=dtype)
            if array.shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        if np.any((self.locked_leg < 0) | (self.locked_leg > LEG_COUNT)):
            raise ValueError("locked_leg must be 0 (none) or a leg number 1-6")

    def __len__(self) -> int:
        return len(self.locked_leg)

    @property
    def point_count(self) -> int:
        """Feature points per posture (0 for pose-form data)."""
        return 0 if self.points_mm is None else self.points_mm.shape[1]

    def select(self, mask: NDArray[np.bool_]) -> MeasurementData:
        """The postures where ``mask`` is true."""
        mask = np.asarray(mask, dtype=bool)
        return MeasurementData(
            self.locked_leg[mask],
            self.readings_mm[mask],
            self.lines[mask],
            None if self.poses is None else self.poses[mask],
            None if self.points_mm is None else self.points_mm[mask],
            None if self.point_covariance_mm2 is None else self.point_covariance_mm2[mask],
        )

    def without_lines(self, lines: Iterable[int]) -> MeasurementData:
        """The postures not from ``lines`` (to exclude rows that have problems)."""
        return self.select(~np.isin(self.lines, list(lines)))

    def locked_rows(self, leg: int) -> NDArray[np.intp]:
        """Indices of the postures with ``leg`` (1–6) locked."""
        return np.flatnonzero(self.locked_leg == leg)


@dataclass(frozen=True, slots=True, eq=False)
class MeasuredPoses:
    """Each posture's measured pose: ``poses`` (N, 6) absolute (mm, rad), ``rotations`` (N, 3, 3)."""

    poses: NDArray[np.float64]
    rotations: NDArray[np.float64]

    @property
    def translations(self) -> NDArray[np.float64]:
        return self.poses[:, :3]


def measured_poses(data: MeasurementData, feature_points_mm: NDArray) -> MeasuredPoses:
    """The pose of every posture: as given, or fitted to the measured points (Kabsch).

    Raises :class:`~hexactl.kinematics.points.DegeneratePointsError` for collinear points;
    :func:`screen_measurements` reports those rows first.
    """
    if data.points_mm is None:
        assert data.poses is not None
        poses = np.array(data.poses)
        return MeasuredPoses(poses, rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5]))
    model = np.asarray(feature_points_mm, dtype=float)[: data.point_count]
    fits = [pose_from_points(model, points) for points in data.points_mm]
    return MeasuredPoses(np.array([fit.pose for fit in fits]), np.array([fit.rotation for fit in fits]))


def screen_measurements(
    data: MeasurementData,
    feature_points_mm: NDArray,
    point_sigma_mm: float,
    distance_tolerance_mm: float | None = None,
    locked_reading_tolerance_mm: float = LOCKED_READING_TOLERANCE_MM,
    legs: LegModel | None = None,
    stroke_mm: tuple[float, float] | None = None,
    zero_readings_mm: NDArray | None = None,
) -> tuple[RowProblem, ...]:
    """Rows that must not be used as they are, one :class:`RowProblem` per finding.

    - measured points collinear (no orientation) or with an inter-point distance off the
      known one by more than ``distance_tolerance_mm`` (default
      ``DISTANCE_TOLERANCE_SIGMAS · √2 · point_sigma_mm``): a mis-sighted target or a typo;
    - a leg marked locked whose reading is more than ``locked_reading_tolerance_mm`` from the
      median of that leg's locked rows: the leg did not hold, or the row is mislabelled;
    - a reading more than :data:`STROKE_READING_TOLERANCE_MM` outside ``stroke_mm`` (the
      actuators' [min, max], when given), where no actuator can be: a typo.
    - a row that repeats an earlier one to the last digit: no instrument measures a
      posture twice alike, so it was pasted or appended twice (counted twice, it would
      claim a better calibration than the data give);
    - a row whose readings ``legs`` (the nominal geometry, when given) explain far better
      with its points in another order: targets swapped in that row.

    Measured points whose typical spread differs from the feature points' by more than
    :data:`SCALE_TOLERANCE` times are in another unit: that is one problem for the whole file
    (line 0), instead of one per row. So are measured poses whose readings ``legs`` (the
    nominal geometry, when given) explain far better with the angles read as radians, the
    positions as metres, or the poses taken as relative to the zero posture (the one at
    ``zero_readings_mm``, when given), and measured points whose readings it explains far better
    with the points' columns in another order (a header naming them wrongly), and readings
    it explains far better with the columns l1 … l6 in another order (legs numbered
    otherwise). So are readings far below what the legs read in the zero posture
    (``zero_readings_mm``, when given), throughout the file: metres, cm or inches.
    """
    problems: list[RowProblem] = []
    unit_problem = _unit_problem(data, feature_points_mm) or _readings_unit_problem(data, zero_readings_mm) or (
        None if legs is None else _pose_unit_problem(data, legs, zero_readings_mm)
        or _label_problem(data, feature_points_mm, legs) or _readings_order_problem(data, feature_points_mm, legs))
    if unit_problem is not None:
        return (unit_problem,)
    if data.points_mm is not None:
        tolerance = (
            DISTANCE_TOLERANCE_SIGMAS * np.sqrt(2.0) * point_sigma_mm
            if distance_tolerance_mm is None
            else distance_tolerance_mm
        )
        model = np.asarray(feature_points_mm, dtype=float)[: data.point_count]
        known = _spread_mm(model)
        for line, points in zip(data.lines, data.points_mm):
            ratio = _spread_mm(points) / known if known > 0.0 else 1.0
            if not 1.0 / SCALE_TOLERANCE <= ratio <= SCALE_TOLERANCE and (unit := _unit_question(ratio)):
                # one line in another unit: its points would be called collinear, or mis-sighted
                problems.append(RowProblem(int(line), f"the measured feature points lie {_spread_mm(points):.3g} "
                                           f"from their centre (median), the geometry's {known:.1f} mm: "
                                           f"{unit}hexactl reads mm; write this line in mm"))
                continue
            try:
                fit = pose_from_points(model, points)
            except DegeneratePointsError as error:
                problems.append(RowProblem(int(line), f"feature points unusable: {error}"))
                continue
            for (i, j), error_mm in zip(combinations(range(len(model)), 2), fit.distance_errors_mm):
                if abs(error_mm) > tolerance:
                    known = float(np.linalg.norm(model[i] - model[j]))
                    problems.append(RowProblem(int(line),
                        f"distance p{i + 1}-p{j + 1} is {known + error_mm:.3f} mm, the feature points are "
                        f"{known:.3f} mm apart (error {error_mm:+.3f} mm, tolerance {tolerance:.3f} mm)",
                        mis_sighting=True))
    if stroke_mm is not None:
        low, high = stroke_mm
        for line, readings in zip(data.lines, data.readings_mm):
            for leg, reading in enumerate(readings, start=1):
                if not low - STROKE_READING_TOLERANCE_MM <= reading <= high + STROKE_READING_TOLERANCE_MM:
                    problems.append(RowProblem(int(line), f"l{leg} reads {reading:.4f} mm, outside the actuators' "
                                               f"stroke [{low:g}, {high:g}] mm where no leg can be: a typo?"))
    problems.extend(_repeated_rows(data))
    if legs is not None:
        problems.extend(_swapped_rows(data, feature_points_mm, legs))
    for leg in range(1, LEG_COUNT + 1):
        rows = data.locked_rows(leg)
        if len(rows) == 0:
            continue
        readings = data.readings_mm[rows, leg - 1]
        median = float(np.median(readings))
        for row, reading in zip(rows, readings):
            if abs(reading - median) > locked_reading_tolerance_mm:
                problems.append(RowProblem(int(data.lines[row]),
                    f"leg {leg} is marked locked but reads {reading:.4f} mm, {reading - median:+.4f} mm from "
                    f"its locked rows' median {median:.4f} mm (tolerance {locked_reading_tolerance_mm:g} mm)"))
    return tuple(sorted(problems, key=lambda problem: problem.line))


STROKE_READING_TOLERANCE_MM = 1.0
"""A reading this far beyond the stroke is not noise (a sensor's is ~0.01 mm): no leg can be there."""


def _repeated_rows(data: MeasurementData) -> list[RowProblem]:
    """A problem for each row equal in every value to an earlier one, naming that one."""
    if len(data) == 0:
        return []
    measured = data.points_mm if data.points_mm is not None else data.poses
    values = np.column_stack([data.locked_leg, data.readings_mm, measured.reshape(len(data), -1)])
    _, first, which = np.unique(values, axis=0, return_index=True, return_inverse=True)
    earliest = first[which.ravel()]
    return [RowProblem(int(data.lines[row]), f"repeats line {int(data.lines[earliest[row]])} exactly: no instrument "
                       "measures a posture twice alike, so it was pasted or appended twice; remove it")
            for row in np.flatnonzero(earliest != np.arange(len(data)))]


POSE_UNIT_MISFIT_MM = 20.0
"""Readings this far (median) from what the nominal geometry gives for the measured poses
are not a calibration's few millimetres: worth asking whether the poses' units are wrong."""


def _pose_unit_problem(data: MeasurementData, legs: LegModel, zero_readings_mm: NDArray | None) -> RowProblem | None:
    """A file-level problem if the measured poses' readings fit far better with the angles
    taken as radians or the positions as metres (the file's units are degrees and mm), or
    with the poses taken as relative to the zero posture, the one the legs reach at
    ``zero_readings_mm`` (None: not tried), as a plan's are (the file's are absolute)."""
    if data.poses is None or len(data) == 0:
        return None
    readings = np.asarray(data.readings_mm)

    def misfit(poses: NDArray) -> float:
        return float(np.median(np.abs(sensor_setpoints_batch(legs, poses) - readings)))

    as_read = misfit(data.poses)
    if as_read <= POSE_UNIT_MISFIT_MM:
        return None
    radians, metres = np.array(data.poses), np.array(data.poses)
    radians[:, 3:] = np.degrees(radians[:, 3:])  # the file's numbers were radians, read as degrees
    metres[:, :3] *= 1000.0
    both = np.hstack((metres[:, :3], radians[:, 3:]))
    units = "hexactl reads degrees and mm; convert the file"
    found = {f"the {name}": (misfit(poses), units) for name, poses in (
        ("angles are radians", radians), ("positions are metres", metres),
        ("angles are radians and positions metres", both))}
    if zero_readings_mm is not None and (home := _zero_posture(legs, zero_readings_mm)) is not None:
        # Relative poses are home + relative in mm and degrees (hexactl.kinematics.pose), so in mm and rad too.
        found["they are relative to the zero posture (home), as a plan's are"] = (misfit(data.poses + home), (
            "a measurement file's poses are absolute (the moving frame in the base frame): add home to each (mm, "
            "degrees), or give the measured feature points"))
    name, (best, remedy) = min(found.items(), key=lambda item: item[1][0])
    if best > as_read / 5.0:
        return None
    return RowProblem(0, f"the readings are {as_read:.3g} mm (median) from what the nominal geometry gives for the "
                         f"measured poses, {best:.3g} mm if {name}: {remedy}")


def _zero_posture(legs: LegModel, zero_readings_mm: NDArray) -> NDArray[np.float64] | None:
    """The pose (mm, rad) the legs reach at ``zero_readings_mm``: forward kinematics from the
    level, centred pose of those leg lengths (a zero posture is one, near enough); None where
    it does not converge."""
    lengths = lengths_from_readings(legs, zero_readings_mm)
    across = np.sum((legs.platform_joints_mm[:, :2] - legs.base_joints_mm[:, :2]) ** 2, axis=1)
    rise = np.sqrt(np.clip(lengths**2 - across, 0.0, None))
    heights = legs.base_joints_mm[:, 2] - legs.platform_joints_mm[:, 2] + rise
    result = forward_kinematics(legs, lengths.tolist(), (0.0, 0.0, float(np.median(heights)), 0.0, 0.0, 0.0))
    return np.array(result.pose) if result.ok else None


LABEL_CHECK_ROWS = 30
"""The rows (a file's first) on which other orders of the feature points are tried: enough
to tell a wrong order from the right one, whose misfit is a calibration's millimetres."""


def _label_problem(data: MeasurementData, feature_points_mm: NDArray, legs: LegModel) -> RowProblem | None:
    """A file-level problem if the readings fit the measured points' poses far better with
    the points in another order than the file's columns name them (up to four points)."""
    if data.points_mm is None or len(data) == 0 or data.point_count > 4:
        return None
    model = np.asarray(feature_points_mm, dtype=float)[:data.point_count]
    found = _better_order(data.points_mm[:LABEL_CHECK_ROWS], data.readings_mm[:LABEL_CHECK_ROWS], model, legs)
    if found is None:
        return None
    as_read, best, swaps = found
    return RowProblem(0, f"the readings are {as_read:.3g} mm (median) from what the nominal geometry gives for the "
                         f"poses of the measured points, {best:.3g} mm if {swaps}: check the file's header (p1, p2, "
                         "… are the geometry's feature_points in their order)")


def _readings_order_problem(data: MeasurementData, feature_points_mm: NDArray, legs: LegModel) -> RowProblem | None:
    """A file-level problem if the readings fit the measured poses far better with the
    columns l1 … l6 in another order: an instrument or a sheet that numbers the legs
    otherwise (the fit would not converge, or converge on a machine that is not there)."""
    rows = slice(0, LABEL_CHECK_ROWS)
    if data.poses is not None:
        poses = np.asarray(data.poses)[rows]
    else:
        model = np.asarray(feature_points_mm, dtype=float)[:data.point_count]
        try:
            poses = np.array([pose_from_points(model, points).pose for points in data.points_mm[rows]])
        except DegeneratePointsError:  # a row problem of its own
            return None
    if len(poses) == 0:
        return None
    predicted, readings = sensor_setpoints_batch(legs, poses), np.asarray(data.readings_mm)[rows]

    def misfit(order: tuple[int, ...]) -> float:  # per row, as two legs swapped leave four right
        return float(np.median(np.sqrt(np.mean((predicted - readings[:, list(order)]) ** 2, axis=1))))

    as_named = tuple(range(LEG_COUNT))
    as_read = misfit(as_named)
    if as_read <= POSE_UNIT_MISFIT_MM:
        return None
    order, best = min(((order, misfit(order)) for order in permutations(as_named) if order != as_named),
                      key=lambda item: item[1])
    if best > min(as_read / 5.0, POSE_UNIT_MISFIT_MM):
        return None
    moved = ", ".join(f"l{column + 1} holds leg {leg + 1}" for column, leg in sorted(
        (column, leg) for leg, column in enumerate(order) if column != leg))
    return RowProblem(0, f"the readings are {as_read:.3g} mm (RMS, median row) from what the nominal geometry gives "
                         f"for the measured poses, {best:.3g} mm if {moved}: the legs are numbered otherwise; check the "
                         "file's header (l1 … l6 are legs 1–6 as the geometry numbers them) and write the readings "
                         "in that order")


def _swapped_rows(data: MeasurementData, feature_points_mm: NDArray, legs: LegModel) -> list[RowProblem]:
    """A problem for each row whose readings fit its points' pose far better with the points
    in another order (up to four points): targets swapped in sighting or in typing. On a
    symmetric target the distances are right, and such a row tilts its pose so far that
    the fit follows it to a machine a metre off."""
    if data.points_mm is None or data.point_count > 4:
        return []
    model = np.asarray(feature_points_mm, dtype=float)[:data.point_count]
    problems = []
    for line, points, readings in zip(data.lines, data.points_mm, data.readings_mm):
        if (found := _better_order(points[None], readings[None], model, legs)) is not None:
            as_read, best, swaps = found
            problems.append(RowProblem(int(line), f"the readings are {as_read:.3g} mm (median) from what the nominal "
                                       f"geometry gives for the pose of this row's points, {best:.3g} mm if {swaps}: "
                                       "targets swapped? correct the row, or measure the posture again"))
    return problems


def _better_order(points: NDArray, readings: NDArray, model: NDArray, legs: LegModel
                  ) -> tuple[float, float, str] | None:
    """(misfit as named, misfit in the best other order, that order in words) when the
    readings of the rows ``points`` (N, K, 3) fit their poses far better with the points in
    another order; misfit: the readings' median distance from the nominal's, mm."""
    def misfit(order: tuple[int, ...]) -> float:
        try:
            poses = np.array([pose_from_points(model, row[list(order)]).pose for row in points])
        except DegeneratePointsError:  # a row problem of its own
            return float("inf")
        return float(np.median(np.abs(sensor_setpoints_batch(legs, poses) - readings)))

    as_named = tuple(range(len(model)))
    as_read = misfit(as_named)
    if not POSE_UNIT_MISFIT_MM < as_read < float("inf"):
        return None
    order, best = min(((order, misfit(order)) for order in permutations(as_named) if order != as_named),
                      key=lambda item: item[1])
    if best > min(as_read / 5.0, POSE_UNIT_MISFIT_MM):
        return None
    return as_read, best, " and ".join(f"the columns named p{column + 1} hold p{point + 1}"
                                       for point, column in enumerate(order) if column != point)


READINGS_UNIT_RATIO = 8.0
"""Readings whose median is this many times below the zero posture's, and of which none
comes within half of it, are not a campaign around the zero posture in mm: every posture
would have every leg drawn in far below it. Metres, cm and inches all fall below."""


def _readings_unit_problem(data: MeasurementData, zero_readings_mm: NDArray | None) -> RowProblem | None:
    """A file-level problem if the legs read far less than in the zero posture throughout
    the file: readings in another unit (their range would pass the stroke's check)."""
    if zero_readings_mm is None or len(data) == 0:
        return None
    zero = float(np.median(zero_readings_mm))
    typical, largest = float(np.median(data.readings_mm)), float(np.max(np.abs(data.readings_mm)))
    if zero <= 0.0 or typical > zero / READINGS_UNIT_RATIO or largest > zero / 2.0:
        return None
    return RowProblem(0, f"the legs read {typical:.4g} (median) and at most {largest:.4g}, in the zero posture "
                         f"{zero:.1f} mm: {_unit_question(typical / zero)}hexactl reads the sensors in mm; convert "
                         "the readings to mm")


def _unit_problem(data: MeasurementData, feature_points_mm: NDArray) -> RowProblem | None:
    """A file-level problem if the measured points are not in mm (their median distance from
    their own centroid against the feature points')."""
    if data.points_mm is None or len(data) == 0:
        return None
    known = _spread_mm(np.asarray(feature_points_mm, dtype=float)[: data.point_count])
    span = _spread_mm(data.points_mm)
    if known <= 0.0 or 1.0 / SCALE_TOLERANCE <= span / known <= SCALE_TOLERANCE:
        return None
    return RowProblem(0, f"the measured feature points lie {span:.3g} from their centre (median), the geometry's "
                         f"{known:.1f} mm: {_unit_question(span / known)}hexactl reads mm; convert the file to mm")


def _spread_mm(points: NDArray) -> float:
    """The median distance of points (..., K, 3) from their centroid (each row's own)."""
    return float(np.median(np.linalg.norm(points - points.mean(axis=-2, keepdims=True), axis=-1)))


_UNITS_IN_MM = {1e-3: "metres", 1e-1: "cm", 1.0 / 25.4: "inches", 1e3: "µm"}
"""What a length in mm reads as in another unit, by that unit (the factor from mm)."""


def _unit_question(ratio: float) -> str:
    """``"are they in UNIT? "`` for the unit whose factor lies within 1.5× of ``ratio``
    (values as read over what mm would give), else nothing."""
    unit = next((name for factor, name in _UNITS_IN_MM.items()
                 if ratio > 0.0 and abs(np.log(ratio / factor)) < np.log(1.5)), None)
    return f"are they in {unit}? " if unit else ""
