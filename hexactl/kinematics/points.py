"""The pose from measured feature points: the paper's section 3.1, done by least squares.

Three or more targets with known moving-frame coordinates are measured in the fixed frame
(theodolites, laser tracker). The rigid transform that best maps the former onto the
latter (Kabsch/Horn, SVD of the cross-covariance) is the platform's pose; the fit
residual and the inter-point distance errors say how much to trust that measurement.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.rotation import euler_from_matrix

MIN_SPREAD_MM = 1.0
"""Point sets whose second principal extent is below this are treated as collinear."""


class DegeneratePointsError(ValueError):
    """The points cannot define an orientation (fewer than three, or collinear)."""


@dataclass(frozen=True, slots=True)
class PointFit:
    """A pose fitted to measured points.

    ``pose`` is absolute (mm, rad); ``residuals_mm`` is each point's distance from its fitted
    position; ``distance_errors_mm`` is, for each pair of points (in ``combinations`` order),
    measured minus known distance: independent of the fit, so it flags a bad reading.
    """

    pose: tuple[float, float, float, float, float, float]
    rotation: NDArray[np.float64]
    residuals_mm: NDArray[np.float64]
    distance_errors_mm: NDArray[np.float64]

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm**2)))

    @property
    def max_distance_error_mm(self) -> float:
        return float(np.max(np.abs(self.distance_errors_mm)))


def pose_from_points(model_points_mm: NDArray, measured_points_mm: NDArray) -> PointFit:
    """Fit the pose mapping moving-frame ``model_points_mm`` (K, 3) onto fixed-frame
    ``measured_points_mm`` (K, 3), K ≥ 3.

    Raises :class:`DegeneratePointsError` for fewer than three or collinear points and
    ``ValueError`` for mismatched shapes or non-finite values.
    """
    model = np.asarray(model_points_mm, dtype=float)
    measured = np.asarray(measured_points_mm, dtype=float)
    if model.ndim != 2 or model.shape[1] != 3 or model.shape != measured.shape:
        raise ValueError(f"points must be two (K, 3) arrays of one shape, got {model.shape} and {measured.shape}")
    if not (np.all(np.isfinite(model)) and np.all(np.isfinite(measured))):
        raise ValueError("points must be finite numbers")
    if len(model) < 3:
        raise DegeneratePointsError(f"a pose needs at least three points, got {len(model)}")
    model_centre, measured_centre = model.mean(axis=0), measured.mean(axis=0)
    model_c, measured_c = model - model_centre, measured - measured_centre
    for name, centred in (("model", model_c), ("measured", measured_c)):
        spread = np.linalg.svd(centred, compute_uv=False)
        if spread[1] < MIN_SPREAD_MM:
            raise DegeneratePointsError(f"the {name} points are collinear (second extent {spread[1]:.3g} mm)")

    u, _, vt = np.linalg.svd(measured_c.T @ model_c)
    reflection_fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ reflection_fix @ vt
    translation = measured_centre - rotation @ model_centre
    residuals = np.linalg.norm(model @ rotation.T + translation - measured, axis=1)
    pairs = list(combinations(range(len(model)), 2))
    distance_errors = np.array(
        [np.linalg.norm(measured[i] - measured[j]) - np.linalg.norm(model[i] - model[j]) for i, j in pairs]
    )
    roll, pitch, yaw = euler_from_matrix(rotation)
    x, y, z = (float(v) for v in translation)
    return PointFit((x, y, z, roll, pitch, yaw), rotation, residuals, distance_errors)
