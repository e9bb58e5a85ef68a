"""The identified quantities: per leg B_i, P_mi and zero length, optionally a sensor gain.

The parameter vector is laid out leg by leg, ``[B_i (x, y, z), P_mi (x, y, z), zero_i]``
for legs 1–6 (42 values, all mm), followed, when gains are identified, by six scale errors
in mm per metre of sensor reading (so every entry is a length and one condition number
compares them all). A leg's length is ``zero_i + (1 + scale_i/1000) · reading``, and the
controller's kinematics applies the scale errors a calibration file carries.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.geometry import CalibrationInfo, Geometry, geometry_from_mapping
from hexactl.kinematics.inverse import LEG_COUNT, LegModel

PARAMETERS_PER_LEG = 7
GEOMETRIC_PARAMETERS = PARAMETERS_PER_LEG * LEG_COUNT
SCALE_UNIT = 1000.0
"""Scale errors are carried as mm per this many mm of reading (per metre)."""
STD_AGREEMENT = 0.02
"""A calibration file's standard deviations and the square roots of its covariance's
diagonal agree within this share of the standard deviation (plus :data:`STD_ROUNDING`)."""
STD_ROUNDING = 5e-4
"""mm (mm per metre for a gain): what rounding a standard deviation to three decimals leaves."""


def _readonly(values: object, shape: tuple[int, ...]) -> NDArray[np.float64]:
    array = np.array(values, dtype=float)
    if array.shape != shape:
        raise ValueError(f"expected shape {shape}, got {array.shape}")
    array.flags.writeable = False
    return array


@dataclass(frozen=True, slots=True, eq=False)
class StructuralParameters:
    """A platform's structural parameters (mm) and optional sensor scale errors.

    ``scale_errors`` (6,) is dimensionless (0 = perfect sensor) or None when not identified.
    The same shape holds standard deviations when a result reports them.
    """

    base_joints_mm: NDArray[np.float64]
    platform_joints_mm: NDArray[np.float64]
    zero_lengths_mm: NDArray[np.float64]
    scale_errors: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "base_joints_mm", _readonly(self.base_joints_mm, (LEG_COUNT, 3)))
        object.__setattr__(self, "platform_joints_mm", _readonly(self.platform_joints_mm, (LEG_COUNT, 3)))
        object.__setattr__(self, "zero_lengths_mm", _readonly(self.zero_lengths_mm, (LEG_COUNT,)))
        if self.scale_errors is not None:
            object.__setattr__(self, "scale_errors", _readonly(self.scale_errors, (LEG_COUNT,)))

    @classmethod
    def from_geometry(cls, geometry: Geometry, with_scales: bool = False) -> StructuralParameters:
        """The parameters of ``geometry``; scale errors 0 when ``with_scales``."""
        return cls(
            np.array(geometry.base_joints),
            np.array(geometry.platform_joints),
            np.array(geometry.zero_lengths),
            np.zeros(LEG_COUNT) if with_scales else None,
        )

    @property
    def has_scales(self) -> bool:
        return self.scale_errors is not None

    @property
    def size(self) -> int:
        return GEOMETRIC_PARAMETERS + (LEG_COUNT if self.has_scales else 0)

    def to_vector(self) -> NDArray[np.float64]:
        per_leg = np.hstack((self.base_joints_mm, self.platform_joints_mm, self.zero_lengths_mm[:, None]))
        vector = per_leg.ravel()
        if self.scale_errors is not None:
            vector = np.concatenate((vector, self.scale_errors * SCALE_UNIT))
        return vector

    @classmethod
    def from_vector(cls, vector: NDArray, with_scales: bool) -> StructuralParameters:
        vector = np.asarray(vector, dtype=float)
        per_leg = vector[:GEOMETRIC_PARAMETERS].reshape(LEG_COUNT, PARAMETERS_PER_LEG)
        scales = vector[GEOMETRIC_PARAMETERS:] / SCALE_UNIT if with_scales else None
        return cls(per_leg[:, 0:3], per_leg[:, 3:6], per_leg[:, 6], scales)

    def legs(self) -> LegModel:
        """The kinematics' view (scale errors 0 when not identified)."""
        scales = np.zeros(LEG_COUNT) if self.scale_errors is None else self.scale_errors
        return LegModel(self.base_joints_mm, self.platform_joints_mm, self.zero_lengths_mm, scales)


def parameter_names(with_scales: bool) -> tuple[str, ...]:
    """Names in vector order: ``B1.x … P1.z, zero1, …, scale1 …``."""
    names = []
    for leg in range(1, LEG_COUNT + 1):
        names += [f"B{leg}.{axis}" for axis in "xyz"] + [f"P{leg}.{axis}" for axis in "xyz"] + [f"zero{leg}"]
    if with_scales:
        names += [f"scale{leg}" for leg in range(1, LEG_COUNT + 1)]
    return tuple(names)


def covariance_problem(info: CalibrationInfo) -> str | None:
    """Why ``info``'s ``parameter_covariance`` contradicts the standard deviations beside it,
    one sentence naming the key and the first parameter that disagrees; None when it agrees.

    hexactl writes each ``*_std_mm`` (and ``sensor_scale_errors_std``) as the square root
    of the covariance's diagonal entry in the parameter vector's order (per leg B x y z,
    P x y z, zero; then the six gains in mm per metre). The controller predicts a move's
    error from the covariance alone, so one that says less than its own standard
    deviations (zeroed, scaled down: an edit or damage) would let any tolerance pass. They
    agree within :data:`STD_AGREEMENT` of the standard deviation plus :data:`STD_ROUNDING`
    (a file rounded by hand); a zero variance never agrees: no measurement knows a
    parameter exactly.
    """
    if info.parameter_covariance is None:
        return None
    variances = np.diag(np.array(info.parameter_covariance, dtype=float))
    with_scales = variances.size > GEOMETRIC_PARAMETERS
    stated = _stated_deviations(info, with_scales)
    if stated is None:
        gains = " and sensor_scale_errors_std" if with_scales else ""
        return ("parameter_covariance: given without base_joints_std_mm, platform_joints_std_mm, zero_lengths_std_mm"
                f"{gains}, which hexactl writes beside it and checks it against: the file was edited or damaged; "
                "calibrate again, or restore the file as hexactl calibrate wrote it")
    implied = np.sqrt(np.clip(variances, 0.0, None))
    bad = np.flatnonzero((variances <= 0.0) | (np.abs(implied - stated) > STD_AGREEMENT * stated + STD_ROUNDING))
    if bad.size == 0:
        return None
    first = int(bad[0])
    key, unit, factor = _deviation_key(first)
    more = f" (and {bad.size - 1} more parameter(s))" if bad.size > 1 else ""
    return (f"parameter_covariance: its diagonal entry {first} (0-based; per leg B x y z, P x y z, zero, then the six "
            f"gains) gives {parameter_names(with_scales)[first]} a standard deviation of "
            f"{implied[first] / factor:.4g}{unit}, but calibration.{key} says {stated[first] / factor:.4g}{unit}{more}: "
            "both come from one identification, so the file was edited or damaged, and its covariance would predict "
            "a wrong error for every move; calibrate again, or restore the file as hexactl calibrate wrote it")


def _stated_deviations(info: CalibrationInfo, with_scales: bool) -> NDArray[np.float64] | None:
    """The file's standard deviations in the covariance's order and units; None if any is missing."""
    parts = (info.base_joints_std_mm, info.platform_joints_std_mm, info.zero_lengths_std_mm)
    if any(part is None for part in parts) or (with_scales and info.sensor_scale_errors_std is None):
        return None
    base, platform, zero = (np.array(part, dtype=float) for part in parts)
    vector = np.hstack((base, platform, zero[:, None])).ravel()
    if with_scales:
        vector = np.concatenate((vector, np.array(info.sensor_scale_errors_std, dtype=float) * SCALE_UNIT))
    return vector


def _deviation_key(index: int) -> tuple[str, str, float]:
    """(the ``[calibration]`` key holding parameter ``index``'s standard deviation, its unit
    as shown, the factor from the covariance's unit to the key's)."""
    if index >= GEOMETRIC_PARAMETERS:
        return f"sensor_scale_errors_std[{index - GEOMETRIC_PARAMETERS}]", "", SCALE_UNIT
    leg, column = divmod(index, PARAMETERS_PER_LEG)
    if column == PARAMETERS_PER_LEG - 1:
        return f"zero_lengths_std_mm[{leg}]", " mm", 1.0
    key = "base_joints_std_mm" if column < 3 else "platform_joints_std_mm"
    return f"{key}[{leg}][{column % 3}]", " mm", 1.0


def leg_columns(leg_index: int) -> slice:
    """Columns of leg ``leg_index`` (0-based) in the parameter vector."""
    return slice(PARAMETERS_PER_LEG * leg_index, PARAMETERS_PER_LEG * (leg_index + 1))


def calibrated_geometry(nominal: Geometry, parameters: StructuralParameters, info: CalibrationInfo,
                        feature_points_mm: NDArray | None = None) -> Geometry:
    """``nominal`` with identified joints, zero lengths and (when identified) sensor scale
    errors, and the ``[calibration]`` table.

    Limits, home, measurement and, when ``parameters`` has none, the sensor scale errors are
    copied from ``nominal`` (the identification used them: see
    :func:`hexactl.calibration.identification.identify`). Identified ``feature_points_mm``
    (K, 3) replace the measurement's: they define the moving frame the joints are in. Raises
    :class:`~hexactl.kinematics.geometry.GeometryError` if the result is not a valid
    geometry (for example the zero posture left the sensor stroke).
    """
    document = nominal.model_dump()
    document.update(
        name=f"{nominal.name} (calibrated)" if nominal.name else "calibrated",
        base_joints=parameters.base_joints_mm.tolist(),
        platform_joints=parameters.platform_joints_mm.tolist(),
        zero_lengths=parameters.zero_lengths_mm.tolist(),
        sensor_scale_errors=(nominal.sensor_scale_errors if parameters.scale_errors is None
                             else parameters.scale_errors.tolist()),
        calibration=info.model_dump(),
    )
    if feature_points_mm is not None:
        document["measurement"] = {**document["measurement"], "feature_points": np.asarray(feature_points_mm).tolist()}
    return geometry_from_mapping(document, "calibrated geometry")
