"""Validation: how far the platform's achieved poses are from the commanded ones.

A validation runs the test motions (:mod:`hexactl.calibration.test_motions`) and measures
where the platform really went: with the instrument on a real platform, by forward
kinematics on the true geometry in simulation. This module only holds and summarises the
outcome, so both paths share it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.test_motions import TestMotion


@dataclass(frozen=True, slots=True, eq=False)
class MotionResult:
    """One test motion's achieved poses ``achieved_relative`` (W, 6), mm/deg from the zero posture."""

    motion: TestMotion
    achieved_relative: NDArray[np.float64]

    @property
    def commanded_relative(self) -> NDArray[np.float64]:
        return np.array(self.motion.waypoints, dtype=float)

    @property
    def errors(self) -> NDArray[np.float64]:
        """Achieved minus commanded, (W, 6), mm and deg."""
        return np.asarray(self.achieved_relative) - self.commanded_relative


@dataclass(frozen=True, slots=True)
class ValidationSummary:
    """Largest and RMS |error| over every waypoint of every motion; position per axis (mm),
    orientation per Euler angle (deg)."""

    max_position_error_mm: float
    max_orientation_error_deg: float
    rms_position_error_mm: float
    rms_orientation_error_deg: float


def summarise_validation(results: Sequence[MotionResult]) -> ValidationSummary:
    errors = np.concatenate([result.errors for result in results])
    return ValidationSummary(
        max_position_error_mm=float(np.max(np.abs(errors[:, :3]))),
        max_orientation_error_deg=float(np.max(np.abs(errors[:, 3:]))),
        rms_position_error_mm=float(np.sqrt(np.mean(errors[:, :3] ** 2))),
        rms_orientation_error_deg=float(np.sqrt(np.mean(errors[:, 3:] ** 2))),
    )


def largest_stroke_error(results: Sequence[MotionResult], strokes: Sequence[float]) -> tuple[float, int]:
    """The largest |error| over every waypoint of ``results`` as a fraction of its axis'
    stroke (``strokes``: six, mm and deg, e.g. the paper's ±600 mm … ±60°), and that axis
    (0–5: x, y, z, roll, pitch, yaw): the paper's "relative error in the range of the stroke"."""
    relative = np.abs(np.concatenate([result.errors for result in results])) / np.asarray(strokes, dtype=float)
    largest = int(np.argmax(relative))
    return float(relative.flat[largest]), largest % 6
