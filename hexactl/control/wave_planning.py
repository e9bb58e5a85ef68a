"""Wave planning and validation, in the caller's thread (never in the loop).

A wave (:class:`~hexactl.control.waves.WaveSpec`) becomes a :class:`WavePlan` only after
its whole path has been checked, from rest:

1. every loop cycle's position (:meth:`~hexactl.control.waves.WavePath.at`, the function
   the loop will run) as a pose relative to the zero posture;
2. the limits of every commanded path (:func:`~hexactl.control.planning.path_violations`:
   stroke, joint cones, envelope, near-singularity, soft limits), in batches, with a look
   at the planning budget (:data:`~hexactl.control.planning.PLANNING_BUDGET_S`) between
   them and between batches of cycles in 1;
3. the legs' speed: set-points by batch IK, the peak change per cycle against the budget
   moves are planned within (``PlanningContext.leg_speed_mm_s``). A move that is too fast
   is stretched in time; a wave is refused, never stretched: its frequency is what was
   asked for;
4. velocity, acceleration and jerk in pose space (finite differences of the positions,
   at rest before and after) against the :class:`~hexactl.control.trajectory.MotionLimits`
   of every commanded motion: a stop mid-wave hands the state to the trajectory
   generator's jerk-limited halt, which needs it within them.

The geometry sets no leg-acceleration limit: the legs' peak acceleration is reported,
not checked (a leg's acceleration follows from the pose-space limits checked in 4).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import degrees

import numpy as np

from hexactl.control.frames import Frame, convert, relative_poses
from hexactl.control.planning import (
    MAX_MOTION_S,
    PlanningBudget,
    PlanningContext,
    Refusal,
    budgeted_path_violations,
    farthest_violation,
)
from hexactl.control.results import ErrorCode
from hexactl.control.trajectory import KinematicState
from hexactl.control.waves import WavePath, WaveSpec
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import sensor_setpoints_batch


_BUDGET_SAMPLES = 50_000
"""Cycles of a wave computed between two looks at the planning budget
(:data:`~hexactl.control.planning.PLANNING_BUDGET_S`; a fraction of a second idle)."""


@dataclass(frozen=True, slots=True)
class WavePlan:
    """A validated wave, ready for the loop: ``path`` in the coordinates of ``frames``
    (None: relative mm/rad; else the tool's pose in the work frame); the peaks over its
    samples: legs' speed mm/s and acceleration mm/s² (and the legs, 1–6, they are on),
    pose velocity per axis (mm/s, deg/s)."""

    path: WavePath
    frames: Frames | None
    peak_leg_speed_mm_s: float
    peak_leg_speed_leg: int
    peak_leg_acceleration_mm_s2: float
    peak_leg_acceleration_leg: int
    peak_pose_velocity: tuple[float, ...]

    def summary(self) -> dict:
        """The plan's figures for a reply."""
        return {"duration_s": self.path.duration_s, "cycles": self.path.spec.cycles, "samples": self.path.samples,
                "peak_leg_speed_mm_s": self.peak_leg_speed_mm_s, "peak_leg_speed_leg": self.peak_leg_speed_leg,
                "peak_leg_acceleration_mm_s2": self.peak_leg_acceleration_mm_s2,
                "peak_leg_acceleration_leg": self.peak_leg_acceleration_leg,
                "peak_pose_velocity": list(self.peak_pose_velocity)}


def plan_wave(context: PlanningContext, start: KinematicState, start_frames: Frames | None,
              spec: WaveSpec) -> WavePlan | Refusal:
    """Plan and validate ``spec`` from the generator state ``start`` (in the coordinates of
    ``start_frames``); the refusal names the limit, the leg or axis, the peak and the bound.
    Never raises for a valid spec."""
    if context.lock is not None:
        return Refusal(ErrorCode.LEG_LOCKED,
                       f"leg {context.lock.leg} is locked: a wave needs all six legs; unlock first")
    if not start.resting:
        return Refusal(ErrorCode.BUSY, "a wave starts from rest: stop first")
    if spec.duration_s > MAX_MOTION_S:
        return Refusal(ErrorCode.PLANNING_FAILED, f"the wave would take {spec.duration_s:.6g} s; a motion may take at "
                       f"most {MAX_MOTION_S:g} s: fewer cycles or a higher frequency")
    home = context.active.home
    frames = None if spec.frame is Frame.ZERO else context.frames
    if spec.frame is not Frame.ZERO and frames is None:
        return Refusal(ErrorCode.INVALID_ARGUMENT, "a wave in the work or tool frame needs the operator's frames")
    origin = start.position if frames == start_frames else convert(start.position, start_frames, frames, home)
    path = WavePath(spec, origin, context.period_s)
    budget, remedy = PlanningBudget(), "fewer cycles"
    rows: list = []
    for begin in range(0, path.samples + 1, _BUDGET_SAMPLES):
        if begin and (refusal := budget.refusal(f"at cycle {begin} of {path.samples}", remedy)):
            return refusal
        rows += [path.at(k) for k in range(begin, min(begin + _BUDGET_SAMPLES, path.samples + 1))]
    positions = np.array(rows, dtype=float)
    relative = relative_poses(frames, positions, home)
    violations = budgeted_path_violations(context, relative, 1, budget, "checking the wave's path", remedy)
    if isinstance(violations, Refusal):
        return violations
    if violations:
        more = f" (and {len(violations) - 1} more)" if len(violations) > 1 else ""
        farthest = farthest_violation(context, relative)
        at_worst = f"; at its farthest, {farthest.message}" if farthest and farthest.message != violations[0].message else ""
        return Refusal(ErrorCode.PATH_VIOLATION, f"the wave leaves the limits: {violations[0].message}{more}{at_worst}",
                       tuple(violations))
    period = context.period_s
    setpoints = sensor_setpoints_batch(context.active.geometry.legs, relative + np.asarray(home))
    speed = np.abs(np.diff(setpoints, axis=0)).max(axis=0) / period
    acceleration = np.abs(np.diff(setpoints, n=2, axis=0)).max(axis=0) / period**2
    fastest = int(np.argmax(speed))
    if speed[fastest] > context.leg_speed_mm_s:
        return Refusal(ErrorCode.PLANNING_FAILED,
                       f"leg {fastest + 1} would move at {speed[fastest]:.1f} mm/s, beyond the legs' speed limit "
                       f"{context.leg_speed_mm_s:g} mm/s: lower the amplitude or the frequency (a wave is never "
                       "slowed down)", details={"kind": "leg_speed", "leg": fastest + 1,
                                                "leg_speed_mm_s": float(speed[fastest]),
                                                "limit_mm_s": context.leg_speed_mm_s})
    if refusal := _pose_limit_refusal(context, positions):
        return refusal
    velocity = np.abs(np.diff(positions, axis=0)).max(axis=0) / period
    hardest = int(np.argmax(acceleration))
    return WavePlan(path, frames, float(speed[fastest]), fastest + 1, float(acceleration[hardest]), hardest + 1,
                    tuple(float(v) for v in (*velocity[:3], *np.degrees(velocity[3:]))))


def _pose_limit_refusal(context: PlanningContext, positions: np.ndarray) -> Refusal | None:
    """The first pose-space velocity, acceleration or jerk beyond ``context.limits`` of the
    (N, 6) ``positions`` (mm/rad; at rest before and after), or None."""
    at_rest = np.repeat(positions[:1], 2, axis=0), np.repeat(positions[-1:], 2, axis=0)
    padded = np.concatenate((at_rest[0], positions, at_rest[1]))
    limits = context.limits
    for order, name, bounds in ((1, "velocity", limits.max_velocity), (2, "acceleration", limits.max_acceleration),
                                (3, "jerk", limits.max_jerk)):
        peaks = np.abs(np.diff(padded, n=order, axis=0)).max(axis=0) / context.period_s**order
        for index, (peak, bound) in enumerate(zip(peaks, bounds)):
            peak = float(peak) if index < 3 else degrees(peak)
            if peak > bound:
                axis, unit = POSE_AXES[index], f"{POSE_UNITS[index]}/s" + ("" if order == 1 else f"^{order}")
                return Refusal(ErrorCode.PLANNING_FAILED,
                               f"the {axis} {name} would reach {peak:.4g} {unit}, beyond the motion limit {bound:g} "
                               f"{unit} (config motion.max_{name}): lower the amplitude or the frequency, or ramp "
                               "over more cycles",
                               details={"kind": f"pose_{name}", "axis": axis, "peak": peak, "limit": bound})
    return None

