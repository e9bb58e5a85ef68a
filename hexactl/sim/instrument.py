"""A simulated 3-D measuring instrument (theodolite pair, laser tracker).

It measures the platform's feature points in the fixed frame, each coordinate with
independent Gaussian noise: what the paper's two theodolites deliver (section 3.1).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.geometry import Geometry
from hexactl.calibration.observations import Instrument
from hexactl.kinematics.rotation import rotation_matrices, rotation_matrix


class SimulatedInstrument:
    """Measures feature points with noise σ per coordinate; seeded, so runs repeat exactly.

    ``feature_points_mm`` (K, 3) are the targets in the moving frame. The generator is the
    instrument's only state: successive measurements draw successive noise.
    """

    def __init__(self, feature_points_mm: NDArray, point_sigma_mm: float, seed: int) -> None:
        if point_sigma_mm < 0:
            raise ValueError(f"point_sigma_mm must be ≥ 0, got {point_sigma_mm}")
        self.feature_points_mm = np.array(feature_points_mm, dtype=float)
        self.feature_points_mm.flags.writeable = False
        self.point_sigma_mm = float(point_sigma_mm)
        self._rng = np.random.default_rng(seed)

    @classmethod
    def for_geometry(cls, geometry: Geometry, seed: int, point_sigma_mm: float | None = None) -> SimulatedInstrument:
        """The instrument of ``geometry``'s ``[measurement]`` table (σ overridable)."""
        sigma = geometry.measurement.point_sigma_mm if point_sigma_mm is None else point_sigma_mm
        return cls(np.array(geometry.measurement.feature_points), sigma, seed)

    def measure(self, pose: Sequence[float]) -> NDArray[np.float64]:
        """Feature points (K, 3) in the fixed frame, mm, of the true absolute ``pose`` (mm, rad)."""
        rotation = rotation_matrix(pose[3], pose[4], pose[5])
        exact = self.feature_points_mm @ rotation.T + np.asarray(pose[:3], dtype=float)
        return exact + self._rng.normal(0.0, self.point_sigma_mm, exact.shape)


def observe(instrument: Instrument, feature_points_mm: NDArray, poses: NDArray, seed: int) -> NDArray[np.float64]:
    """The instrument's own observations (N, K, m; radians and mm) of the feature points
    (K, 3, moving frame) at the true absolute poses (N, 6; mm, rad), each with its native
    noise (seeded)."""
    poses = np.asarray(poses, dtype=float)
    rotations = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    points = np.einsum("nij,kj->nki", rotations, np.asarray(feature_points_mm, dtype=float)) + poses[:, None, :3]
    noise = np.random.default_rng(seed).normal(size=points.shape[:2] + (instrument.size,))
    return instrument.predict(points) + noise * instrument.sigmas
