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
