"""The instruments' own observations of a feature point, with their native noise.

The paper measures with two theodolites (a horizontal and a vertical angle from each of
two stations); a laser tracker measures a range and two angles from one station. Each
model here predicts its observations of a point in the fixed frame, their Jacobian, and
the point they imply (triangulation, or the tracker's spherical coordinates inverted).

``full`` adjusts the points these observations imply, each weighted by its own covariance
``(Jᵀ·Σ⁻¹·J)⁻¹`` propagated from the native noise: to first order that is the same
estimate as adjusting the angles and ranges themselves, and it keeps every other part of
the toolkit (screening, the other methods, the report) on points. (A theodolite pair's
fourth angle per point is redundant: its χ² degree of freedom is not counted.)

Angles are radians, lengths mm. A station's pose is (x, y, z, roll, pitch, yaw) in the
fixed frame, mm and degrees: its local x axis is horizontal angle 0, its xy plane the
horizontal (vertical angle = elevation above it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.kinematics.rotation import rotation_matrix

_REFINEMENTS = 2
MIN_BASELINE_MM = 1.0
"""Two theodolites closer than this stand at one place: from there each point's rays meet
at the station itself, so nothing can be triangulated."""


@dataclass(frozen=True, slots=True, eq=False)
class Station:
    """Where an instrument stands: ``pose_mm_deg`` in the fixed frame."""

    pose_mm_deg: tuple[float, float, float, float, float, float]

    @property
    def origin(self) -> NDArray[np.float64]:
        return np.array(self.pose_mm_deg[:3], dtype=float)

    @property
    def rotation(self) -> NDArray[np.float64]:
        return rotation_matrix(*np.radians(self.pose_mm_deg[3:]))

    def local(self, points: NDArray) -> NDArray[np.float64]:
        """Points (..., 3) in the station's frame: Rᵀ·(p − o)."""
        return (np.asarray(points, dtype=float) - self.origin) @ self.rotation

    def direction(self, horizontal: NDArray, vertical: NDArray) -> NDArray[np.float64]:
        """Unit vectors (..., 3), fixed frame, of the angles seen from here."""
        local = np.stack((np.cos(vertical) * np.cos(horizontal), np.cos(vertical) * np.sin(horizontal),
                          np.sin(vertical)), axis=-1)
        return local @ self.rotation.T


def _angles(local: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(horizontal, vertical, ∂horizontal/∂local, ∂vertical/∂local) of station-frame points."""
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    planar2 = x * x + y * y
    planar = np.sqrt(planar2)
    range2 = planar2 + z * z
    d_horizontal = np.stack((-y / planar2, x / planar2, np.zeros_like(x)), axis=-1)
    d_vertical = np.stack((-x * z / (range2 * planar), -y * z / (range2 * planar), planar / range2), axis=-1)
    return np.arctan2(y, x), np.arctan2(z, planar), d_horizontal, d_vertical


def wrapped(angles: NDArray) -> NDArray[np.float64]:
    """Angles (rad) into (−π, π]: the difference of two angles."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=float), 2.0 * np.pi)


@dataclass(frozen=True, slots=True, eq=False)
class Theodolites:
    """Two theodolites at ``stations`` A and B, each angle with noise ``angle_sigma_rad``.
    Observations per point: (horizontal A, vertical A, horizontal B, vertical B)."""

    stations: tuple[Station, Station]
    angle_sigma_rad: float
    size = 4

    @property
    def sigmas(self) -> NDArray[np.float64]:
        return np.full(4, self.angle_sigma_rad)

    def predict(self, points: NDArray) -> NDArray[np.float64]:
        return np.stack([angle for station in self.stations for angle in _angles(station.local(points))[:2]], axis=-1)

    def jacobian(self, points: NDArray) -> NDArray[np.float64]:
        """∂ observations / ∂ point (fixed frame): (..., 4, 3)."""
        rows = []
        for station in self.stations:
            _, _, d_horizontal, d_vertical = _angles(station.local(points))
            rows += [d_horizontal @ station.rotation.T, d_vertical @ station.rotation.T]
        return np.stack(rows, axis=-2)

    def points(self, observations: NDArray) -> NDArray[np.float64]:
        """The points (..., 3) the angles imply by least squares (the four angles equally
        weighted): from the middle of the shortest segment between the two stations' rays,
        refined by Gauss–Newton (two steps reach rounding at these precisions). Raises
        ``ValueError`` for parallel rays or stations less than :data:`MIN_BASELINE_MM` apart."""
        observations = np.asarray(observations, dtype=float)
        points = self._ray_midpoints(observations)
        for _ in range(_REFINEMENTS):
            jacobian = self.jacobian(points)
            normal = np.swapaxes(jacobian, -1, -2) @ jacobian
            gradient = np.swapaxes(jacobian, -1, -2) @ wrapped(observations - self.predict(points))[..., None]
            points = points + np.linalg.solve(normal, gradient)[..., 0]
        return points

    def _ray_midpoints(self, observations: NDArray) -> NDArray[np.float64]:
        a, b = self.stations
        if (baseline := float(np.linalg.norm(a.origin - b.origin))) < MIN_BASELINE_MM:
            raise ValueError(f"the two theodolites' stations coincide ({baseline:.3g} mm apart): from one place the "
                             "rays of a point meet only at the station, so it cannot be triangulated")
        u = a.direction(observations[..., 0], observations[..., 1])
        v = b.direction(observations[..., 2], observations[..., 3])
        w = a.origin - b.origin
        uv, uw, vw = np.sum(u * v, axis=-1), np.sum(u * w, axis=-1), np.sum(v * w, axis=-1)
        denominator = 1.0 - uv * uv
        if np.any(denominator < 1e-12):
            raise ValueError("the two theodolites' rays are parallel for some point: it cannot be triangulated")
        s, t = (uv * vw - uw) / denominator, (vw - uv * uw) / denominator
        return 0.5 * ((a.origin + s[..., None] * u) + (b.origin + t[..., None] * v))


@dataclass(frozen=True, slots=True, eq=False)
class LaserTracker:
    """A laser tracker at ``station``: range (noise ``range_sigma_mm``), horizontal and
    vertical angle (``angle_sigma_rad``). Observations per point: (range, horizontal, vertical)."""

    station: Station
    range_sigma_mm: float
    angle_sigma_rad: float
    size = 3

    @property
    def sigmas(self) -> NDArray[np.float64]:
        return np.array([self.range_sigma_mm, self.angle_sigma_rad, self.angle_sigma_rad])

    def predict(self, points: NDArray) -> NDArray[np.float64]:
        local = self.station.local(points)
        horizontal, vertical, _, _ = _angles(local)
        return np.stack((np.linalg.norm(local, axis=-1), horizontal, vertical), axis=-1)

    def jacobian(self, points: NDArray) -> NDArray[np.float64]:
        local = self.station.local(points)
        _, _, d_horizontal, d_vertical = _angles(local)
        d_range = local / np.linalg.norm(local, axis=-1, keepdims=True)
        return np.stack((d_range, d_horizontal, d_vertical), axis=-2) @ self.station.rotation.T

    def points(self, observations: NDArray) -> NDArray[np.float64]:
        observations = np.asarray(observations, dtype=float)
        direction = self.station.direction(observations[..., 1], observations[..., 2])
        return self.station.origin + observations[..., 0:1] * direction


Instrument = Theodolites | LaserTracker


def point_covariance(instrument: Instrument, points: NDArray) -> NDArray[np.float64]:
    """The covariance (..., 3, 3), mm², of the points the instrument's observations imply,
    at ``points`` (..., 3): (Jᵀ·Σ⁻¹·J)⁻¹ with Σ the observations' native noise."""
    jacobian = instrument.jacobian(points) / instrument.sigmas[:, None]
    return np.linalg.inv(np.swapaxes(jacobian, -1, -2) @ jacobian)
