"""Wave planning and validation, in the caller's thread (never in the loop).

A wave (:class:`~hexactl.control.waves.WaveSpec`) becomes a :class:`WavePlan` only after
its whole path has been checked, from rest:

1. every loop cycle's position (:meth:`~hexactl.control.waves.WavePath.at`, the function
   the loop will run) as a pose relative to the zero posture;
2. the limits of every commanded path (:func:`~hexactl.control.planning.path_violations`:
   stroke, joint cones, envelope, near-singularity, soft limits), in batches, with a look
   at the planning budget (:data:`~hexactl.control.planning.PLANNING_BUDGET_S`) between
   them and between batches of cycles in 1; a refusal says where the path first leaves
   a limit, how far it goes, and the largest amplitudes that stay inside;
3. the legs' speed: set-points by batch IK, the peak change per cycle against the budget
   moves are planned within (``PlanningContext.leg_speed_mm_s``). A move that is too fast
   is stretched in time; a wave is refused, never stretched: its frequency is what was
   asked for;
4. velocity, acceleration and jerk in pose space (finite differences of the positions,
   at rest before and after) against the :class:`~hexactl.control.trajectory.MotionLimits`
   of every commanded motion.

A stop mid-wave brakes along the wave's own path (:class:`~hexactl.control.wave_player.WavePlayer`):
the wave's time slows to a stop, so the platform comes to rest on a pose of the path just
validated (a wave has no goal: a per-axis brake ends off its path, beyond its amplitude).
:func:`brake_time_s` finds, from the path's peak velocity, acceleration and jerk, how long
that takes within the motion limits; the plan carries it.

The geometry sets no leg-acceleration limit: the legs' peak acceleration is reported,
not checked (a leg's acceleration follows from the pose-space limits checked in 4).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import degrees, floor, log10

import numpy as np

from hexactl.control.frames import Frame, convert, relative_poses
from hexactl.control.planning import (
    MAX_MOTION_S,
    OUTSIDE_SOFT_LIMITS,
    PlanningBudget,
    PlanningContext,
    Refusal,
    budgeted_path_violations,
    farthest_violation,
    path_violations,
    thinned,
)
from hexactl.control.results import ErrorCode
from hexactl.control.waves import WavePath, WaveSpec
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS, RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import sensor_setpoints_batch
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg


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
    brake_s: float
    """How long a stop takes to slow the wave's time from rate 1 to 0 (:func:`brake_time_s`), s."""

    def summary(self) -> dict:
        """The plan's figures for a reply."""
        return {"duration_s": self.path.duration_s, "cycles": self.path.spec.cycles, "samples": self.path.samples,
                "peak_leg_speed_mm_s": self.peak_leg_speed_mm_s, "peak_leg_speed_leg": self.peak_leg_speed_leg,
                "peak_leg_acceleration_mm_s2": self.peak_leg_acceleration_mm_s2,
                "peak_leg_acceleration_leg": self.peak_leg_acceleration_leg,
                "peak_pose_velocity": list(self.peak_pose_velocity)}


def plan_wave(context: PlanningContext, start: RelativeMmRad | ToolInWorkMmRad, start_frames: Frames | None,
              spec: WaveSpec) -> WavePlan | Refusal:
    """Plan and validate ``spec`` about the pose ``start`` it starts from at rest (in the
    coordinates of ``start_frames``, as the generator's); the refusal names the limit, the
    leg or axis, the peak and the bound. Whether it may start now (at rest, all six legs)
    is :func:`~hexactl.control.preconditions.check_wave`'s. Never raises for a valid spec."""
    if spec.duration_s > MAX_MOTION_S:
        return Refusal(ErrorCode.PLANNING_FAILED, f"the wave would take {spec.duration_s:.6g} s; a motion may take at "
                       f"most {MAX_MOTION_S:g} s: fewer cycles or a higher frequency")
    home = context.active.home
    frames = None if spec.frame is Frame.ZERO else context.frames
    if spec.frame is not Frame.ZERO and frames is None:
        return Refusal(ErrorCode.INVALID_ARGUMENT, "a wave in the work or tool frame needs the operator's frames")
    origin = start if frames == start_frames else convert(start, start_frames, frames, home)
    path = WavePath(spec, origin, context.period_s)
    budget, remedy = PlanningBudget(), "fewer cycles"
    positions = _positions(path, budget, remedy)
    if isinstance(positions, Refusal):
        return positions
    relative = relative_poses(frames, positions, home)
    violations = budgeted_path_violations(context, relative, 1, budget, "checking the wave's path", remedy)
    if isinstance(violations, Refusal):
        return violations
    if violations and (at_start := path_violations(context, relative[:1], 1)):
        first = at_start[0]
        remedy = OUTSIDE_SOFT_LIMITS if first.kind.startswith("soft") else "move it back inside first"
        return Refusal(ErrorCode.PATH_VIOLATION, f"the wave would start beyond a limit, where the platform rests: "
                       f"{first.message}: {remedy}", tuple(at_start))
    if violations:
        more = f" (and {len(violations) - 1} more)" if len(violations) > 1 else ""
        farthest = farthest_violation(context, relative)
        at_worst = f"; at its farthest, {farthest.message}" if farthest and farthest.message != violations[0].message else ""
        fitting = _fitting_amplitudes(context, path, frames, positions, relative)
        fit = f"; {_describe_fit(fitting)}" if fitting else ""
        return Refusal(ErrorCode.PATH_VIOLATION,
                       f"the wave leaves the limits: {violations[0].message}{more}{at_worst}{fit}", tuple(violations),
                       details={"fitting_amplitudes": fitting} if fitting else {})
    period = context.period_s
    setpoints = _setpoints(context, relative)
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
                    tuple(float(v) for v in (*velocity[:3], *np.degrees(velocity[3:]))),
                    brake_time_s(_pose_peaks(positions, period), context.limits.in_mm_rad()))


def _positions(path: WavePath, budget: PlanningBudget, remedy: str) -> np.ndarray | Refusal:
    """Every cycle's position on ``path`` (:meth:`WavePath.at`, as the loop runs it), (N, 6),
    with a look at ``budget`` between batches of cycles: or its refusal."""
    rows: list = []
    for begin in range(0, path.samples + 1, _BUDGET_SAMPLES):
        if begin and (refusal := budget.refusal(f"at cycle {begin} of {path.samples}", remedy)):
            return refusal
        rows += [path.at(k) for k in range(begin, min(begin + _BUDGET_SAMPLES, path.samples + 1))]
    return np.array(rows, dtype=float)


_FIT_HALVINGS = 10
"""Halvings of the search for the amplitudes that fit: to 1/1024 of those asked."""

_FIT_ALLOWANCE_S = 1.0
"""The longest the search for the amplitudes that fit may take, s: a hint, that a refusal
does not wait on (a long wave in the tool frame would take seconds)."""


def _fitting_amplitudes(context: PlanningContext, path: WavePath, frames: Frames | None, positions: np.ndarray,
                        relative: np.ndarray) -> dict[str, float] | None:
    """The largest amplitudes, in the proportions asked, whose path breaks no limit
    (:func:`~hexactl.control.planning.path_violations`) and which are not too fast (the
    legs' speed, the pose's motion limits: :func:`_pace`; a fit that is found too fast was
    the next refusal), each rounded down to 3 significant digits, by axis name (mm, deg);
    None where none is found (from a start beyond a limit) or the search outlasts
    :data:`_FIT_ALLOWANCE_S`.

    The search assesses candidates at the samples the full wave's path check keeps (at
    most a path step apart at full amplitude, closer at less), in the ramps and the first
    period between them: ``positions`` (the full wave's, by cycle) scaled about the start,
    which is the wave with scaled amplitudes, but for the tool frame's, which
    :meth:`WavePath.at` gives for each. What it finds is then checked as the wave's
    validation would check it, every cycle, and lowered by 1 % until it passes (its own
    samples fall elsewhere)."""
    spec, start = path.spec, np.asarray(path.start, dtype=float)
    home = context.active.home
    indices = thinned(pose_mm_rad_to_mm_deg(relative), context.path_step_mm, context.path_step_deg)
    # Between the ramps every period repeats the first: the ramps and one period stand for all.
    times = indices * path.period_s
    indices = indices[(times <= path.ramp_s + 1.0 / spec.frequency_hz) | (times >= path.duration_s - path.ramp_s)]
    offsets = positions[indices] - start

    def fits(scale: float) -> bool:
        if spec.frame is Frame.TOOL:
            scaled = WavePath(_with_amplitudes(spec, {name: axis.amplitude * scale for name, axis in spec.axes.items()}),
                              path.start, path.period_s)
            candidate = np.array([scaled.at(int(k)) for k in indices], dtype=float)
        else:
            candidate = start + scale * offsets
        return not path_violations(context, relative_poses(frames, candidate, home), 1)

    budget = PlanningBudget(_FIT_ALLOWANCE_S)
    low, high = 0.0, 1.0
    for _ in range(_FIT_HALVINGS):
        if budget.spent():
            return None
        middle = (low + high) / 2
        low, high = (middle, high) if fits(middle) else (low, middle)
    amplitudes = {name: _round_down(axis.amplitude * low) for name, axis in spec.axes.items()}
    while low > 0.0 and not budget.spent():
        wave = _positions(WavePath(_with_amplitudes(spec, amplitudes), path.start, path.period_s), budget, "")
        if isinstance(wave, Refusal):
            return None
        relative = relative_poses(frames, wave, home)
        violations = budgeted_path_violations(context, relative, 1, budget, "", "")
        if isinstance(violations, Refusal):
            return None
        pace = 0.0 if violations else _pace(context, relative, wave)
        if not violations and pace <= 1.0:
            return amplitudes
        # each peak grows with the amplitude: one over its limit by k is fitted by 1/k of it
        factor = 0.99 / pace if pace > 1.0 else 0.99
        amplitudes = {name: _round_down(amplitude * factor) for name, amplitude in amplitudes.items()}
    return None


def _setpoints(context: PlanningContext, relative: np.ndarray) -> np.ndarray:
    """The legs' sensor set-points (N, 6) of (N, 6) relative mm/rad poses."""
    return sensor_setpoints_batch(context.active.geometry.legs, relative + np.asarray(context.active.home))


def _pace(context: PlanningContext, relative: np.ndarray, positions: np.ndarray) -> float:
    """How far the fastest of a wave's paces goes against its limit (1: on it): the legs'
    speed, and the pose's velocity, acceleration and jerk, of its (N, 6) ``relative``
    poses and ``positions`` (mm/rad), as :func:`plan_wave` checks them."""
    leg_speed = np.abs(np.diff(_setpoints(context, relative), axis=0)).max() / context.period_s
    limits = context.limits.in_mm_rad()
    peaks = _pose_peaks(positions, context.period_s)
    return max(leg_speed / context.leg_speed_mm_s,
               *(float(np.max(peak / np.asarray(bound))) for peak, bound in zip(peaks, limits)))


def _with_amplitudes(spec: WaveSpec, amplitudes: dict[str, float]) -> WaveSpec:
    """``spec`` with ``amplitudes`` by axis name (mm, deg), phases kept."""
    return spec.model_copy(update={"axes": {name: axis.model_copy(update={"amplitude": amplitudes[name]})
                                            for name, axis in spec.axes.items()}})


def _round_down(value: float) -> float:
    """``value`` towards zero to 3 significant digits: a fitting amplitude stays fitting."""
    if value == 0.0:
        return 0.0
    digits = 2 - floor(log10(abs(value)))
    scale = 10.0**abs(digits)
    magnitude = floor(abs(value) * scale) / scale if digits >= 0 else floor(abs(value) / scale) * scale
    return float(np.copysign(magnitude, value))


def _describe_fit(fitting: dict[str, float]) -> str:
    """The amplitudes that fit, for a refusal's message."""
    described = ", ".join(f"{name} {amplitude:.3g} {POSE_UNITS[POSE_AXES.index(name)]}"
                          for name, amplitude in fitting.items())
    return f"amplitudes that stay inside the limits: {described}"


def _pose_peaks(positions: np.ndarray, period_s: float) -> list[np.ndarray]:
    """Peak |velocity|, |acceleration|, |jerk| per axis (mm/rad) of the (N, 6) ``positions``
    (at rest before and after), by finite differences."""
    at_rest = np.repeat(positions[:1], 2, axis=0), np.repeat(positions[-1:], 2, axis=0)
    padded = np.concatenate((at_rest[0], positions, at_rest[1]))
    return [np.abs(np.diff(padded, n=order, axis=0)).max(axis=0) / period_s**order for order in (1, 2, 3)]


BRAKE_MARGIN = 0.9
"""The brake slows the wave's time at this fraction of the fastest rate the bounds allow:
room for the loop's time grid and the finite differences the peaks come from."""

BRAKE_OVER_OWN_PEAK = 1.05
"""Where the wave's own peak acceleration or jerk on an axis is within 5 % of the limit,
the brake bounds that axis by its peak times this instead: the bounds use the path's peaks
wherever the brake is, and the limit itself would leave no room to slow down."""


def brake_time_s(peaks: list[np.ndarray], limits: tuple[list[float], list[float], list[float]]) -> float:
    """How long (s) a stop takes to slow a wave's time from rate 1 to 0 along its path:
    ``peaks`` are the path's peak |p'|, |p''| and |p'''| per axis (mm/rad, by time;
    :func:`_pose_peaks`), ``limits`` the velocity, acceleration and jerk limits per axis
    (mm/rad).

    The brake plays the path at time s(τ) with the rate r = ds/dτ = 1 - e(τ/T), e the
    quintic smoothstep (acceleration continuous where the brake starts, zero at rest). The
    pose's acceleration is then p''·r² + p'·ṙ and its jerk p'''·r³ + 3·p''·r·ṙ + p'·r̈
    (the path's curvature in p''), bounded per axis by the path's peaks wherever the brake
    is: conservative. Its velocity p'·r stays within the wave's own."""
    velocity, acceleration, jerk = (np.asarray(peak, dtype=float) for peak in peaks)
    limit_a = np.maximum(np.asarray(limits[1], dtype=float), BRAKE_OVER_OWN_PEAK * acceleration)
    limit_j = np.maximum(np.asarray(limits[2], dtype=float), BRAKE_OVER_OWN_PEAK * jerk)
    u = np.linspace(0.0, 1.0, 2001)[1:, None]
    r = 1.0 - u**3 * (10.0 + u * (-15.0 + 6.0 * u))
    de = 30.0 * u**2 * (1.0 - u) ** 2  # de/du
    dde = np.abs(60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))  # |d²e/du²|
    with np.errstate(divide="ignore", invalid="ignore"):
        # acceleration: A·r² + V·e'·x ≤ limit, with x = 1/T
        rate_a = np.where(velocity * de > 0.0, (limit_a - acceleration * r**2) / (velocity * de), np.inf)
        # jerk: V·|e''|·x² + 3·A·r·e'·x + J·r³ ≤ limit
        a2, b, c = velocity * dde, 3.0 * acceleration * r * de, limit_j - jerk * r**3
        root = np.where(a2 > 0.0, (-b + np.sqrt(b * b + 4.0 * a2 * c)) / (2.0 * a2),
                        np.where(b > 0.0, c / b, np.inf))
    rate = float(min(rate_a.min(), root.min()))
    if not np.isfinite(rate) or rate <= 0.0:  # nothing moves (or no bound): at rest where it is
        return 0.0
    return 1.0 / (BRAKE_MARGIN * rate)


def _pose_limit_refusal(context: PlanningContext, positions: np.ndarray) -> Refusal | None:
    """The first pose-space velocity, acceleration or jerk beyond ``context.limits`` of the
    (N, 6) ``positions`` (mm/rad; at rest before and after), or None."""
    limits = context.limits
    all_peaks = _pose_peaks(positions, context.period_s)
    for order, name, bounds in ((1, "velocity", limits.max_velocity), (2, "acceleration", limits.max_acceleration),
                                (3, "jerk", limits.max_jerk)):
        peaks = all_peaks[order - 1]
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

