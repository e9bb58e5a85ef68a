"""The platform geometry: the contract shared by the controller and the calibration tools.

A :class:`Geometry` is what a geometry or calibration TOML file holds (see
config/platform.toml for the annotated nominal one). It is frozen and fully validated on
construction: every number finite, shapes right, joints distinct, limits consistent and
the zero posture inside the actuator stroke and not near-singular. Units: mm and degrees,
as in the file.
"""

from __future__ import annotations

from functools import cached_property
from itertools import combinations
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from hexactl.kinematics.inverse import LegModel, sensor_setpoints, twist_jacobian
from hexactl.kinematics.axes import POSE_AXES, AbsoluteMmDeg, RelativeMmDeg
from hexactl.kinematics.numbers import Number, SixNumbers, WholeNumber
from hexactl.kinematics.one_line import is_one_line
from hexactl.kinematics.validation_messages import describe_validation_error

MIN_JOINT_SEPARATION_MM = 1.0
"""Joints closer than this are taken as a typing error (two legs on one joint)."""

COVARIANCE_SIZES = (42, 48)
"""A parameter covariance covers the 42 structural parameters, and the six sensor scale errors when identified."""

MIN_NOISE_SIGMA_MM = 1e-6
"""The smallest noise (1σ) an instrument or a sensor may be given, mm: a nanometre, below any real
one's. An identification weighs each residual by 1/σ²: far below it the weights overflow."""

MAX_NOISE_SIGMA_MM = 1e3
"""The largest, mm: a metre measures nothing of a platform (and far above, 1/σ² underflows)."""

MAX_SENSOR_SCALE_ERROR = 0.01
"""A sensor gain error beyond 1 % is a unit or lead mistake, not a calibration (lead errors are ~1e-4)."""

Vector3 = Annotated[tuple[Number, Number, Number], Field(description="[x, y, z], mm")]


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, strict=False)


class Limits(_Strict):
    """Actuator, joint and pose limits."""

    stroke: tuple[Number, Number] = Field(description="sensor range [min, max], mm")
    base_cone_deg: Number = Field(gt=0, lt=90, description="base joint cone-angle limit, deg")
    platform_cone_deg: Number = Field(gt=0, lt=90, description="platform joint cone-angle limit, deg")
    pose_min: RelativeMmDeg = Field(description="pose envelope lower bound, relative to the zero posture, mm and deg")
    pose_max: RelativeMmDeg = Field(description="pose envelope upper bound, relative to the zero posture, mm and deg")
    leg_velocity_mm_s: Number = Field(gt=0, description="fastest allowed actuator speed, mm/s")
    max_jacobian_condition: Number = Field(gt=1, description="near-singularity threshold")
    # Plausibility bounds of a calibration around the nominal geometry (see
    # hexactl.kinematics.plausibility; the defaults' reasons: docs/calibration.md).
    calibration_joint_tolerance_mm: Number = Field(
        default=60.0, gt=0, description="a calibrated joint centre's largest distance from its nominal position, mm")
    calibration_zero_length_tolerance_mm: Number = Field(
        default=60.0, gt=0, description="a calibrated zero length's largest difference from the nominal, mm")
    calibration_home_tolerance_mm: Number = Field(
        default=10.0, gt=0, description="a calibration's zero posture: largest distance from the nominal's, mm")
    calibration_home_tolerance_deg: Number = Field(
        default=0.5, gt=0, description="a calibration's zero posture: largest roll, pitch or yaw difference, deg")

    @model_validator(mode="after")
    def _ordered(self) -> Limits:
        if not self.stroke[0] < self.stroke[1]:
            raise ValueError(f"stroke: min {self.stroke[0]} must be below max {self.stroke[1]}")
        for axis, low, high in zip(POSE_AXES, self.pose_min, self.pose_max):
            if not low <= 0.0 <= high:
                raise ValueError(
                    f"pose_min/pose_max: {axis} range [{low}, {high}] must contain the zero posture (0)"
                )
        return self


def noise_sigma_problem(sigma_mm: float) -> str | None:
    """What is wrong with ``sigma_mm`` as a noise, 1σ in mm (an instrument's, a sensor's); None if nothing."""
    if not MIN_NOISE_SIGMA_MM <= sigma_mm <= MAX_NOISE_SIGMA_MM:
        return (f"{sigma_mm:g} is not a noise (1σ) from {MIN_NOISE_SIGMA_MM:g} to {MAX_NOISE_SIGMA_MM:g} mm, a nanometre "
                "to a metre: no instrument or sensor measures outside it (check the unit: mm)")
    return None


class Measurement(_Strict):
    """The external instrument's targets and noise."""

    feature_points: tuple[Vector3, ...] = Field(
        min_length=3, description="targets on the platform, moving frame, mm"
    )
    point_sigma_mm: Number = Field(description="instrument noise, 1 sigma per coordinate, mm")
    feature_point_sigma_mm: Number = Field(
        default=0.0,
        description="how well feature_points are known, 1 sigma per coordinate, mm (0: exactly); above 0 the "
                    "calibration identifies them too, with this prior",
    )

    @field_validator("point_sigma_mm")
    @classmethod
    def _noise(cls, sigma: float) -> float:
        if problem := noise_sigma_problem(sigma):
            raise ValueError(problem)
        return sigma

    @field_validator("feature_point_sigma_mm")
    @classmethod
    def _prior(cls, sigma: float) -> float:
        if sigma != 0.0 and (problem := noise_sigma_problem(sigma)):
            raise ValueError(f"{problem}; or 0: known exactly")
        return sigma

    @model_validator(mode="after")
    def _not_collinear(self) -> Measurement:
        points = np.array(self.feature_points)
        singular = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
        if singular[1] < MIN_JOINT_SEPARATION_MM:
            raise ValueError("feature_points: the points are collinear; a pose needs three non-collinear points")
        return self


def _one_line_warning(text: str) -> str:
    if not (is_one_line(text) and text.strip()):
        raise ValueError(f"{text[:120]!r} is not allowed: a warning is one line of text, without control characters "
                         "(load-calibration, status and the log print each as a line of its own)")
    return text


def _one_line_or_none(text: str) -> str:
    if text and not is_one_line(text):
        raise ValueError(f"{text[:120]!r} is not allowed: a name is one line of text, without control characters "
                         "(hexactl check and the log print it)")
    return text


IdentificationWarning = Annotated[str, AfterValidator(_one_line_warning)]
"""One of a calibration's warnings. Found from outside: a file's warning with an escape
sequence cleared the operator's terminal when load-calibration and status printed it."""

GeometryName = Annotated[str, AfterValidator(_one_line_or_none)]
"""A geometry's name or a calibration's nominal: empty, or one line of text."""


class CalibrationInfo(_Strict):
    """Metadata of an identified geometry (the ``[calibration]`` table)."""

    method: str = Field(description="identification method, e.g. leglock or full")
    created: str = Field(description="ISO 8601 time of the identification")
    input_sha256: str = Field(description="hash of the measurement data file")
    postures: WholeNumber = Field(ge=1, description="postures used")
    residual_rms_mm: Number = Field(ge=0, description="fit residual, RMS, mm")
    nominal: GeometryName = Field(default="", description="the nominal geometry it started from")
    base_joints_std_mm: tuple[Vector3, ...] | None = None
    platform_joints_std_mm: tuple[Vector3, ...] | None = None
    zero_lengths_std_mm: SixNumbers | None = None
    sensor_scale_errors_std: SixNumbers | None = Field(
        default=None, description="standard deviations of the identified sensor_scale_errors (dimensionless)"
    )
    parameter_covariance: tuple[tuple[Number, ...], ...] | None = Field(
        default=None,
        description="covariance of the identified parameters, 42×42 (per leg B x y z, P x y z, zero; mm²) or 48×48 "
                    "with the six sensor scale errors after them (in mm per metre of reading): what the controller's "
                    "predicted accuracy is computed from",
    )
    notes: str = ""
    status: Literal["ok", "weakly determined"] | None = Field(
        default=None, description="the identification's status: ok, or weakly determined (written, but the data leave "
        "commanded poses uncertain: warnings say how); absent from files written before it was kept here")
    warnings: tuple[IdentificationWarning, ...] = Field(default=(), description="what the identification warned of, as calibrate printed "
                                      "it; load_calibration and validate_calibration answer with them")

    @field_validator("base_joints_std_mm", "platform_joints_std_mm", "zero_lengths_std_mm", "sensor_scale_errors_std")
    @classmethod
    def _deviations(cls, values: tuple | None) -> tuple | None:
        if values is not None and np.min(values) < 0.0:
            raise ValueError(f"a standard deviation cannot be negative, got {float(np.min(values)):g}: the file was "
                             "edited or damaged; calibrate again")
        return values

    @field_validator("parameter_covariance")
    @classmethod
    def _covariance(cls, rows: tuple[tuple[float, ...], ...] | None) -> tuple[tuple[float, ...], ...] | None:
        if rows is None:
            return rows
        size = len(rows)
        if size not in COVARIANCE_SIZES or any(len(row) != size for row in rows):
            raise ValueError(f"must be a square matrix of size {' or '.join(map(str, COVARIANCE_SIZES))}, got "
                             f"{size} rows of {sorted({len(row) for row in rows})} values")
        matrix = np.array(rows)
        if not np.allclose(matrix, matrix.T, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(np.diag(matrix))))):
            raise ValueError("must be symmetric (a covariance): the file was edited or damaged; calibrate again")
        if np.min(np.diag(matrix)) < 0.0:
            raise ValueError("has a negative variance on its diagonal: the file was edited or damaged; calibrate again")
        # A negative variance along some combination of parameters makes the predicted error
        # there zero (or too small) and lets a move's tolerance pass; rounding of an identified
        # covariance leaves eigenvalues of about -1e-16 of the largest, far inside this bound.
        eigenvalues = np.linalg.eigvalsh(matrix)
        if eigenvalues[0] < -1e-9 * max(eigenvalues[-1], 0.0):
            # With the scale errors (mm per metre of reading) an eigenvector mixes them with
            # lengths: its eigenvalue then has no one unit.
            unit = " mm²" if size == COVARIANCE_SIZES[0] else ", in the parameters' mixed units (mm, mm per metre)"
            raise ValueError(f"is not positive semi-definite (eigenvalue {eigenvalues[0]:.3g}{unit}: a negative "
                             "variance of a parameter combination, which no covariance has): the file was edited or "
                             "damaged; calibrate again")
        return rows


class Geometry(_Strict):
    """A platform's nominal or calibrated geometry (mm, deg)."""

    name: GeometryName = ""
    base_joints: tuple[Vector3, Vector3, Vector3, Vector3, Vector3, Vector3] = Field(
        description="base joint centres B_i, fixed frame, mm"
    )
    platform_joints: tuple[Vector3, Vector3, Vector3, Vector3, Vector3, Vector3] = Field(
        description="platform joint centres P_mi, moving frame, mm"
    )
    zero_lengths: SixNumbers = Field(description="joint-to-joint leg length at sensor reading 0, mm")
    sensor_scale_errors: SixNumbers = Field(
        default=(0.0,) * 6,
        description="per-leg sensor gain error e_i, dimensionless: leg length = zero_length + (1 + e_i)·reading "
                    "(a ball screw's lead error; identified by `hexactl calibrate --scales`)",
    )
    home: AbsoluteMmDeg = Field(description="zero posture in the fixed frame [x, y, z, roll, pitch, yaw], mm and deg")
    limits: Limits
    measurement: Measurement
    calibration: CalibrationInfo | None = None

    @model_validator(mode="before")
    @classmethod
    def _scale_errors_from_older_files(cls, data: object) -> object:
        """Calibration files written before the kinematics applied sensor gains kept them under
        ``[calibration]``; their joints and zero lengths were identified with those gains, so
        the gains belong in the model: moved to the top level (where a file gives both, the
        top level's are kept and the old key must agree, or validation names the conflict)."""
        if isinstance(data, dict) and isinstance(data.get("calibration"), dict) and "sensor_scale_errors" in data["calibration"]:
            calibration = dict(data["calibration"])
            older = calibration.pop("sensor_scale_errors")
            data = {**data, "calibration": calibration}
            if older is not None:
                if "sensor_scale_errors" in data and list(data["sensor_scale_errors"]) != list(older):
                    raise ValueError("sensor_scale_errors and calibration.sensor_scale_errors differ: the latter is an older "
                                     "file's place for them; remove it, keeping the values the controller should apply")
                data["sensor_scale_errors"] = older
        return data

    @model_validator(mode="after")
    def _consistent(self) -> Geometry:
        for key in ("base_joints", "platform_joints"):
            joints = getattr(self, key)
            for i, j in combinations(range(6), 2):
                if (distance := np.linalg.norm(np.subtract(joints[i], joints[j]))) < MIN_JOINT_SEPARATION_MM:
                    raise ValueError(f"{key}: joints {i + 1} and {j + 1} coincide ({distance:.3f} mm apart, less than "
                                     f"{MIN_JOINT_SEPARATION_MM:g} mm): two legs on one joint is a typing error; "
                                     "coordinates are in mm, not metres")
        for i, length in enumerate(self.zero_lengths):
            if length <= 0:
                raise ValueError(f"zero_lengths: leg {i + 1} has non-positive zero length {length}")
        for i, error in enumerate(self.sensor_scale_errors):
            if abs(error) > MAX_SENSOR_SCALE_ERROR:
                raise ValueError(
                    f"sensor_scale_errors: leg {i + 1} has {error:g}, beyond ±{MAX_SENSOR_SCALE_ERROR:g}: a sensor "
                    f"this far off is in another unit or has the wrong lead; fix the sensor's configuration"
                )
        low, high = self.limits.stroke
        for i, reading in enumerate(self.zero_readings_mm()):
            if not low <= reading <= high:
                shown = f"{reading:.3f}" if abs(reading) < 1e6 else f"{reading:.3g}"  # not 300 digits of a typo's 1e300
                raise ValueError(
                    f"limits.stroke: leg {i + 1} needs sensor reading {shown} mm in the zero posture, outside the "
                    f"stroke [{low}, {high}]: check the stroke, and zero_lengths[{i}], base_joints[{i}], "
                    f"platform_joints[{i}] and home (mm, deg)"
                )
        jacobian, _ = twist_jacobian(self.legs, self.home.in_radians())
        condition = float(scaled_conditions(jacobian[None], self.characteristic_length_mm)[0])
        if condition == np.inf:
            raise ValueError("the zero posture is singular: the joints do not form a working hexapod")
        if condition > self.limits.max_jacobian_condition:
            raise ValueError(
                f"limits.max_jacobian_condition: the zero posture's Jacobian condition is {condition:.1f}, above this "
                f"limit of {self.limits.max_jacobian_condition:g}: every pose near it would be refused as near-singular, "
                f"the way back to it too; it is an upper bound (config/platform.toml has 60): raise it above "
                f"{condition:.1f}, or check the joints"
            )
        return self

    @cached_property
    def legs(self) -> LegModel:
        """The structural parameters as the kinematics consumes them."""
        return LegModel(
            np.array(self.base_joints), np.array(self.platform_joints), np.array(self.zero_lengths),
            np.array(self.sensor_scale_errors),
        )

    def zero_readings_mm(self) -> np.ndarray:
        """The six sensor readings in the zero posture, mm."""
        return np.asarray(sensor_setpoints(self.legs, self.home.in_radians()), dtype=float)

    @property
    def identification_warnings(self) -> list[str]:
        """What the identification that wrote this calibration warned of (weakly determined,
        the instrument's frame, …); none for a geometry file."""
        return list(self.calibration.warnings) if self.calibration is not None else []

    @cached_property
    def characteristic_length_mm(self) -> float:
        """Mean platform-joint radius: scales rotations to lengths in conditioning figures."""
        return float(np.mean(np.linalg.norm(np.array(self.platform_joints), axis=1)))


def scaled_conditions(jacobians: np.ndarray, characteristic_length_mm: float) -> np.ndarray:
    """Condition numbers of (N, 6, 6) twist Jacobians with their rotation columns (mm/rad)
    divided by ``characteristic_length_mm``, so that both halves are dimensionless → (N,),
    ``inf`` where singular: what ``[limits] max_jacobian_condition`` bounds."""
    scaled = jacobians * np.array([1.0, 1.0, 1.0] + [1.0 / characteristic_length_mm] * 3)
    singular = np.linalg.svd(scaled, compute_uv=False)
    largest, smallest = singular[:, 0], singular[:, -1]
    return np.divide(largest, smallest, out=np.full(len(singular), np.inf), where=smallest > 0)


def limits_differences(limits: Limits, reference: Limits) -> list[str]:
    """The ``[limits]`` keys whose values differ from ``reference``'s, as ``key: value (reference)``.

    A calibration identifies joints and zero lengths; the limits are the hardware's and
    must stay those of the nominal geometry.
    """
    ours, theirs = limits.model_dump(), reference.model_dump()
    return [f"{key}: {ours[key]} (hardware: {theirs[key]})" for key in ours if ours[key] != theirs[key]]


class GeometryError(ValueError):
    """A geometry could not be accepted; the message names each key and its problem."""


def geometry_from_mapping(data: object, source: str = "geometry") -> Geometry:
    """Validate parsed file content into a :class:`Geometry`.

    Raises :class:`GeometryError` listing every problem as ``source: key: problem``.
    """
    try:
        return Geometry.model_validate(data)
    except ValidationError as error:
        raise GeometryError(describe_validation_error(error, source, model=Geometry)) from None
