"""Whether a calibration may be swapped in: what every start calibration and every load
must be (:func:`acceptance_refusal`), and what the swap must keep from where the platform
is (:func:`swap_refusal`). Poses relative to the zero posture; legs in sensor mm."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from math import isfinite

import numpy as np
from numpy.typing import NDArray

from hexactl.control.config import ControllerConfig
from hexactl.control.core import ControlState, CoreSnapshot
from hexactl.control.frames import convert, relative_poses
from hexactl.control.planning import ActiveGeometry, assess_path, piecewise_line
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.kinematics.geometry import Geometry, limits_differences
from hexactl.kinematics.plausibility import implausibilities
from hexactl.kinematics.workspace import assess_readings

RAMP_SAMPLES = 11
"""A calibration change is checked at this many fractions of its set-point ramp (0, 0.1 … 1)."""


def acceptance_refusal(geometry: Geometry, what: str, nominal: Geometry) -> CommandResult | None:
    """The refusal (``invalid_geometry``) unless ``geometry``'s ``[limits]`` are the
    hardware's (``nominal``'s: no calibration file may widen what is enforced) and each of
    its parameters lies within the plausibility bounds of the nominal one
    (:mod:`hexactl.kinematics.plausibility`). ``what`` names it in the message."""
    if differences := limits_differences(geometry.limits, nominal.limits):
        return CommandResult.failure(
            ErrorCode.INVALID_GEOMETRY,
            f"{what}: its [limits] differ from the hardware's (" + "; ".join(differences)
            + "): a calibration may change joints and zero lengths only; limits come from the nominal geometry",
            differences=differences,
        )
    if problems := implausibilities(geometry, nominal):
        return CommandResult.failure(ErrorCode.INVALID_GEOMETRY, _implausible_message(what, problems),
                                     implausible=problems)
    return None


def swap_refusal(s: CoreSnapshot, new: ActiveGeometry, config: ControllerConfig) -> CommandResult | float:
    """The refusal if swapping ``new`` in now would leave the limits: along the set-point
    ramp to it, at the commanded pose, along the running move and the rest of the playing
    sequence, or by a set-point change larger than ``calibration_max_change_mm`` while
    enabled (only then is it ramped in); else that change, mm."""
    if refusal := _ramp_refusal(s, new):
        return refusal
    violations = assess_path(new.geometry, _remaining_path(s, new, config), 0, config.path_step_mm,
                             config.path_step_deg)
    if violations:
        return CommandResult.failure(ErrorCode.INVALID_GEOMETRY,
                                     f"calibration {new.calibration_id} refused: {violations[0].message}",
                                     violations=[asdict(v) for v in violations])
    change = max(abs(a - b) for a, b in zip(new.setpoints_at(s.pose_command), s.setpoints))
    if s.state is ControlState.ENABLED and change > config.calibration_max_change_mm:
        return CommandResult.failure(ErrorCode.CALIBRATION_CHANGE_TOO_LARGE,
                                     f"calibration {new.calibration_id} would move a leg by {change:.2f} mm "
                                     f"(limit {config.calibration_max_change_mm:g} mm), too far to ramp in while "
                                     "enabled: check the file; if it is right, stop and disable first (disabled, "
                                     "nothing is ramped: the next enable holds where it puts the measured legs)",
                                     change_mm=change)
    return change


def _remaining_path(s: CoreSnapshot, new: ActiveGeometry, config: ControllerConfig) -> NDArray:
    """The poses (relative to ``new``'s zero posture, mm/rad) the platform will take from the
    commanded pose through the running move's goal and the rest of the playing sequence: a
    straight line to each goal in its own coordinates (the tool's pose in the work frame of
    its frames, or relative), as the loop runs it once ``new`` is in force."""
    step_mm, step_deg = config.path_step_mm, config.path_step_deg
    frames = s.frames
    position = convert(s.pose_command, None, frames, s.active.home)  # where it is commanded now
    pieces = [relative_poses(frames, np.array([position]), new.home)]
    goals = [(s.goal, frames)] if s.goal is not None else []
    if s.sequence is not None:
        goals += [(segment.goal, segment.frames) for segment in s.sequence.remaining]
    for goal, goal_frames in goals:
        line = piecewise_line([convert(position, frames, goal_frames, new.home), goal], step_mm, step_deg)[1:]
        pieces.append(relative_poses(goal_frames, line, new.home))
        position, frames = goal, goal_frames
    return np.concatenate(pieces)


def _ramp_refusal(s: CoreSnapshot, new: ActiveGeometry) -> CommandResult | None:
    """The refusal if a pose the platform passes through while the set-points ramp
    (linearly, in the core) from those being sent to ``new``'s at the commanded pose
    leaves the limits, by the new geometry or by the active one (which of the two
    describes the machine is what the swap decides, so both must hold).
    :data:`RAMP_SAMPLES` fractions; with set-points not all known (an actuator not heard
    from while disabled) there is nothing to ramp from, and nothing is checked."""
    if not all(isfinite(v) for v in s.setpoints):
        return None
    fractions = np.linspace(0.0, 1.0, RAMP_SAMPLES)
    start = np.array(s.setpoints)
    end = np.array(new.setpoints_at(s.pose_command))
    ramp = start + np.outer(fractions, end - start)
    guess = s.pose_command.in_degrees()
    for model, which in ((new, "the new calibration"), (s.active, "the active one")):
        for fraction, assessment in zip(fractions, assess_readings(model.geometry, ramp, guess)):
            if assessment is None or assessment.violations:
                problem = (assessment.violations[0].message if assessment is not None
                           else "the set-points have no pose (forward kinematics does not converge)")
                return CommandResult.failure(
                    ErrorCode.INVALID_GEOMETRY,
                    f"calibration {new.calibration_id} refused: at ramp fraction {fraction:.2f} of the change to it, "
                    f"by {which}: {problem}; load it nearer the zero posture, or check the file",
                    ramp_fraction=float(fraction),
                    violations=[asdict(v) for v in assessment.violations] if assessment is not None else [])
    return None


def _implausible_message(what: str, problems: Sequence[str]) -> str:
    return (f"{what} refused: it cannot be a calibration of this platform: " + "; ".join(problems)
            + ". A calibration identifies one machine of the nominal design, whose parameters lie within "
            "millimetres of the nominal ones: check that the file is this platform's calibration, identified "
            "from the nominal geometry in use; if the machine really differs this much from its design, "
            "describe it in a nominal geometry of its own")
