"""Predicted accuracy at the tool point, from the active calibration's parameter covariance.

A calibration file carries the covariance of the parameters it identified
(``[calibration] parameter_covariance``); propagated through the kinematics at a pose, it
says how far the tool point (the tool frame's origin, the pivot) may be from where it is
commanded, 1σ (:func:`hexactl.calibration.uncertainty.point_accuracy`). It is computed
where a request is answered (``validate_pose``, a move with a tolerance, ``status``),
never in the loop: a few 6×6 products per request.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import isfinite
from typing import Any

import numpy as np

from hexactl.calibration.uncertainty import point_accuracy
from hexactl.control.planning import ActiveGeometry
from hexactl.control.results import CommandResult, ErrorCode

NO_COVARIANCE = ("the active geometry carries no parameter covariance (the nominal geometry, or a calibration file "
                 "written before files carried one): calibrate to get a predicted accuracy")


def predicted_accuracy(active: ActiveGeometry, tool_point_mm: Sequence[float],
                       pose_relative_mm_rad: Sequence[float]) -> dict[str, Any] | None:
    """The predicted 1σ error at ``tool_point_mm`` (platform frame, mm) with the platform
    commanded to ``pose_relative_mm_rad`` (relative to the zero posture, mm and rad), as
    the API reports it; None without a covariance."""
    calibration = active.geometry.calibration
    if calibration is None or calibration.parameter_covariance is None:
        return None
    accuracy = point_accuracy(active.geometry.legs, np.array(calibration.parameter_covariance),
                              active.absolute_from_relative_mm_rad(pose_relative_mm_rad), tool_point_mm)
    return {"position_mm": accuracy.position_mm, "position_axes_mm": list(accuracy.position_axes_mm),
            "orientation_deg": accuracy.orientation_deg, "tool_point_mm": [float(v) for v in tool_point_mm]}


def tolerance_refusal(tolerance_mm: float | None, accuracy: dict[str, Any] | None) -> CommandResult | None:
    """The refusal of a move whose predicted position error at the tool point exceeds
    ``tolerance_mm`` (None: no tolerance asked), or that has no prediction to check."""
    if tolerance_mm is None:
        return None
    if isinstance(tolerance_mm, bool) or not isinstance(tolerance_mm, (int, float)) or not (
            isfinite(tolerance_mm) and tolerance_mm > 0):
        return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"tolerance_mm {tolerance_mm!r}: a positive number of mm")
    if accuracy is None:
        return CommandResult.failure(ErrorCode.ACCURACY_INSUFFICIENT, f"a tolerance of {tolerance_mm:g} mm cannot be "
                                     f"checked: {NO_COVARIANCE}, or move without a tolerance")
    if accuracy["position_mm"] > tolerance_mm:
        return CommandResult.failure(
            ErrorCode.ACCURACY_INSUFFICIENT,
            f"predicted error at the tool point {accuracy['position_mm']:.3g} mm (1σ) exceeds the tolerance "
            f"{tolerance_mm:g} mm: calibrate with more or better-spread postures, or relax the tolerance",
            predicted_accuracy=accuracy)
    return None
