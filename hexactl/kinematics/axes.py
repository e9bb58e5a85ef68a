"""The pose's axes, their units at the edges, the name of each pose convention, and what
makes six values a pose.

Standard library only, so that the command line parses a pose without loading numpy;
the conversions are in :mod:`hexactl.kinematics.pose`.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import isfinite
from typing import TypeAlias

POSE_AXES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")
"""Axis names in pose order; the first three in mm, the last three in degrees at the edges."""

POSE_UNITS: tuple[str, ...] = ("mm", "mm", "mm", "deg", "deg", "deg")

RelativeMmDeg: TypeAlias = tuple[float, float, float, float, float, float]
"""Relative to the zero posture, mm and degrees: what the API, the CLI and files carry."""

RelativeMmRad: TypeAlias = tuple[float, float, float, float, float, float]
"""Relative to the zero posture, mm and radians: what planning and the loop work in."""

AbsoluteMmRad: TypeAlias = tuple[float, float, float, float, float, float]
"""In the fixed frame, mm and radians: what the kinematics works in."""


def validate_pose_values(pose: Sequence[float]) -> str | None:
    """None when ``pose`` is six finite numbers, else a sentence naming the problem."""
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        return "a pose is six numbers [x, y, z, roll, pitch, yaw]"
    if len(values) != 6:
        return f"a pose is six numbers [x, y, z, roll, pitch, yaw], got {len(values)}"
    bad = [POSE_AXES[i] for i, v in enumerate(values) if not isfinite(v)]
    if bad:
        return f"pose {', '.join(bad)} is not a finite number"
    return None
