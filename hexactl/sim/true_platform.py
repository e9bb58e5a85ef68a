"""A simulated physical platform: the nominal geometry plus seeded manufacturing errors.

The calibration simulations, and the CAN simulator as its physical platform, use the
returned :class:`~hexactl.kinematics.geometry.Geometry` as ground truth: the geometry
the real machine has but nobody knows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexactl.kinematics.geometry import Geometry, geometry_from_mapping
from hexactl.kinematics.inverse import LEG_COUNT


@dataclass(frozen=True, slots=True)
class ManufacturingErrors:
    """Standard deviations of the manufacturing and assembly errors.

    Each joint centre moves by an isotropic Gaussian error of ``joint_sigma_mm`` per axis,
    each zero length by ``zero_length_sigma_mm`` (the paper's situation: machining and
    assembly tolerances of a few millimetres), each sensor's gain by
    ``sensor_scale_sigma`` (dimensionless; a ball screw's lead error is ~1e-4, default 0:
    the paper's sensors are exact).
    """

    joint_sigma_mm: float = 2.0
    zero_length_sigma_mm: float = 3.0
    sensor_scale_sigma: float = 0.0


def true_geometry(nominal: Geometry, seed: int, errors: ManufacturingErrors = ManufacturingErrors()) -> Geometry:
    """``nominal`` with seeded random joint and zero-length errors (same seed, same platform).

    Limits, home and measurement targets are the nominal ones: the design values, which
    the controller also uses. Raises :class:`~hexactl.kinematics.geometry.GeometryError`
    if the errors are so large that the result is not a working platform.
    """
    rng = np.random.default_rng(seed)
    document = nominal.model_dump()
    document.update(
        name=f"simulated true platform (seed {seed})",
        base_joints=(np.array(nominal.base_joints) + rng.normal(0.0, errors.joint_sigma_mm, (LEG_COUNT, 3))).tolist(),
        platform_joints=(np.array(nominal.platform_joints) + rng.normal(0.0, errors.joint_sigma_mm, (LEG_COUNT, 3))).tolist(),
        zero_lengths=(np.array(nominal.zero_lengths) + rng.normal(0.0, errors.zero_length_sigma_mm, LEG_COUNT)).tolist(),
        # Drawn last, so a platform of a given seed has the same joints with or without them.
        sensor_scale_errors=(np.array(nominal.sensor_scale_errors)
                             + rng.normal(0.0, errors.sensor_scale_sigma, LEG_COUNT)).tolist(),
        calibration=None,
    )
    return geometry_from_mapping(document, f"true platform (seed {seed})")
