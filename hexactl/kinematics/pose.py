"""Pose conventions.

A pose is (x, y, z, roll, pitch, yaw): the moving frame's origin in the fixed frame and
its orientation T = Rz(yaw)·Ry(pitch)·Rx(roll).

- *Relative* poses, in mm and degrees, are what users type and send (CLI, API,
  sequences): offsets from the zero posture ``home``, component by component.
- *Absolute* poses, in mm and radians, are what the kinematics works with. Measurement
  files carry absolute poses (in mm and degrees).

One name per convention, for every pose held as six floats (arrays of poses keep numpy's
types; the functions below convert between the conventions):
:data:`~hexactl.kinematics.axes.RelativeMmDeg`, :data:`~hexactl.kinematics.axes.RelativeMmRad`,
:data:`~hexactl.kinematics.axes.AbsoluteMmRad`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray


_DEG_TO_RAD = np.array([1.0, 1.0, 1.0, np.pi / 180.0, np.pi / 180.0, np.pi / 180.0])


def pose_mm_deg_to_mm_rad(pose_mm_deg: Sequence[float] | NDArray) -> NDArray[np.float64]:
    """(…, 6) pose in mm/deg to mm/rad."""
    return np.asarray(pose_mm_deg, dtype=float) * _DEG_TO_RAD


def pose_mm_rad_to_mm_deg(pose_mm_rad: Sequence[float] | NDArray) -> NDArray[np.float64]:
    """(…, 6) pose in mm/rad to mm/deg."""
    return np.asarray(pose_mm_rad, dtype=float) / _DEG_TO_RAD


def absolute_from_relative(
    home_mm_deg: Sequence[float], relative_mm_deg: Sequence[float] | NDArray
) -> NDArray[np.float64]:
    """Absolute pose (mm, rad) of a pose relative to the zero posture (mm, deg); (…, 6)."""
    return pose_mm_deg_to_mm_rad(np.asarray(home_mm_deg, dtype=float) + np.asarray(relative_mm_deg, dtype=float))


def relative_from_absolute(
    home_mm_deg: Sequence[float], absolute_mm_rad: Sequence[float] | NDArray
) -> NDArray[np.float64]:
    """Pose relative to the zero posture (mm, deg) of an absolute pose (mm, rad); (…, 6)."""
    return pose_mm_rad_to_mm_deg(absolute_mm_rad) - np.asarray(home_mm_deg, dtype=float)
