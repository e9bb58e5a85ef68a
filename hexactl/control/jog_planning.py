"""Jog planning, in the caller's thread: a velocity becomes a move to the first limit ahead.

A jog at velocity v (mm/s, deg/s) in a frame heads from where the motion is along
``requested_goal(v·s)`` (the relative move of s seconds at v: component by component in
the zero and work frames, on the tool's own axes in the tool frame, so a rotation turns
about the pivot point). :func:`plan_jog` finds how far it may go:

1. the goals of s = Δ, 2Δ, … up to :data:`JOG_HORIZON_S` (Δ: at most ``path_step_mm`` /
   ``path_step_deg`` of travel) are checked against every limit a move is: the hardware's
   (stroke, joint cones, envelope, near-singularity) and the operator's soft limits;
2. between the last that passes and the first that does not, bisection finds the limit to
   :data:`BOUNDARY_TOLERANCE` of a step;
3. the move to that goal is planned and validated whole like any move
   (:func:`~hexactl.control.planning.plan_path`, from the generator's state: leg speeds,
   the blend from a motion under way), at the velocity scale that makes its cruise the
   requested velocity (all of it if the motion limits allow).

So the jog decelerates to rest exactly on the limit (the trajectory generator plans the
braking), and nothing is refused or clamped when it gets there. When no limit lies
within the horizon, the plan ends at the horizon and the facade extends it on a renewal
once less than :data:`JOG_EXTEND_S` is left.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import ceil

import numpy as np
from numpy.typing import NDArray

from hexactl.control.frames import Frame, convert, relative_poses, requested_goal
from hexactl.control.jog import JogPlan
from hexactl.control.planning import (
    OUTSIDE_SOFT_LIMITS,
    PlanningContext,
    Refusal,
    StartExcess,
    Waypoint,
    plan_path,
    soft_limits_broken,
    tolerated_excess,
)
from hexactl.control.results import ErrorCode
from hexactl.control.trajectory import KinematicState
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS, RelativeMmDeg, ToolInWorkMmDeg
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg
from hexactl.kinematics.workspace import Violation, ViolationKind, check_poses

JOG_HORIZON_S = 4.0
"""How far ahead a jog is planned, in seconds of travel at its velocity, when no limit is
nearer: planning samples every loop period, so its work grows with the plan's length."""

JOG_EXTEND_S = 1.5
"""A renewal re-plans the jog from where it is once less than this is left of its plan
(it is renewed every fraction of a second, so the motion never reaches the horizon)."""

MAX_JOG_CANDIDATES = 2000
"""Goals checked along the direction at most (then Δ is the horizon over this)."""

BOUNDARY_TOLERANCE = 1e-6
"""The limit is found to this fraction of a step (2 mm: 2 nm), and the jog ends that much
inside it."""

_BISECTIONS = 21  # 2**-21 < BOUNDARY_TOLERANCE
_SHRINK = 0.98  # a goal whose move (not the line to it) breaks a limit is brought this much nearer
_SHRINK_ATTEMPTS = 5


def plan_jog(context: PlanningContext, start: KinematicState, start_frames: Frames | None,
             velocity: Sequence[float], frame: Frame, deadman_ns: int) -> JogPlan | Refusal:
    """The jog at ``velocity`` (six finite numbers, not all zero: mm/s and deg/s) in
    ``frame`` from the generator's state ``start`` (in the coordinates of ``start_frames``),
    each renewal lasting ``deadman_ns``; the refusal if no move of it can be validated."""
    velocity = tuple(float(v) for v in velocity)
    frames = None if frame is Frame.ZERO else context.frames
    home = context.active.home
    origin = convert(start.position, start_frames, frames, home)

    def goal(seconds: float) -> RelativeMmDeg | ToolInWorkMmDeg:
        reached = requested_goal([v * seconds for v in velocity], frame, True, start.position, start_frames,
                                 context.frames, home)
        assert not isinstance(reached, str), "a relative move is always a goal"
        return reached

    # a limit it starts beyond (by a hair, held on it): the jog may go back inside, no further out
    tolerated = tolerated_excess(context, relative_poses(frames, np.array([goal(0.0).in_radians()]), np.asarray(home))[0])

    def broken(seconds: Sequence[float]) -> list[list[Violation]]:
        return _violations_each(context, frames, [goal(s).in_radians() for s in seconds], tolerated)

    step_s = _step_s(context, velocity)
    candidates = np.arange(1, ceil(JOG_HORIZON_S / step_s) + 1) * step_s
    first = next((n for n, found in enumerate(broken(candidates)) if found), None)
    if first is None:
        seconds, end, to_limit = JOG_HORIZON_S, f"the horizon ({JOG_HORIZON_S:g} s of travel; renewals extend it)", False
    else:
        inside, outside = (candidates[first - 1] if first else 0.0), candidates[first]
        for _ in range(_BISECTIONS):
            middle = (inside + outside) / 2
            if broken([middle])[0]:
                outside = middle
            else:
                inside = middle
        # a hair inside: the trajectory's samples reach the goal only to rounding (~1e-13)
        seconds, end, to_limit = max(0.0, inside - step_s * BOUNDARY_TOLERANCE), _limit_name(broken([outside])[0][0]), True
        if seconds == 0.0 and tolerated is not None:  # no goal inside the limits this way: none to rest on
            return Refusal(ErrorCode.PATH_VIOLATION, f"the platform is beyond the limit ahead already "
                           f"({broken([outside])[0][0].message}): jog the other way, back inside"
                           + (f" ({OUTSIDE_SOFT_LIMITS})" if tolerated.soft else ""))
    # At the limit already (no travel): the pace of the velocity asked, over a step of it.
    paced_s = seconds if seconds > 0.0 else step_s
    speed = _speed(context, origin, goal(paced_s).in_radians(), paced_s)
    for _ in range(_SHRINK_ATTEMPTS):
        plan = plan_path(context, start, [Waypoint(goal(seconds), None, speed)], start_frames)
        if plan.ok or plan.refusal is None or plan.refusal.code is not ErrorCode.PATH_VIOLATION:
            break
        seconds *= _SHRINK  # the blend from a motion under way, or the tool frame's path, is not the line
    if not plan.ok:
        assert plan.refusal is not None
        return plan.refusal
    (segment,) = plan.segments
    return JogPlan(frame.value, velocity, segment, speed, end, to_limit, deadman_ns)


def _step_s(context: PlanningContext, velocity: Sequence[float]) -> float:
    """Seconds of jog between checked goals: at most one path step of travel."""
    translation = max(abs(v) for v in velocity[:3])
    rotation = max(abs(v) for v in velocity[3:])
    steps = [step for step in (context.path_step_mm / translation if translation else None,
                               context.path_step_deg / rotation if rotation else None) if step is not None]
    return max(min(steps), JOG_HORIZON_S / MAX_JOG_CANDIDATES)


def _speed(context: PlanningContext, origin: Sequence[float], goal: Sequence[float], seconds: float) -> float:
    """The velocity scale (0, 1] whose cruise covers ``origin`` → ``goal`` (mm, rad) in
    ``seconds``: with phase synchronisation the axis nearest its limit cruises at its
    scaled limit and the others in proportion."""
    velocity_limits = context.limits.in_mm_rad()[0]
    needed = max(abs(g - o) / seconds / limit for g, o, limit in zip(goal, origin, velocity_limits))
    return float(min(1.0, needed)) if needed > 0.0 else 1.0


def _limit_name(violation: Violation) -> str:
    """The limit ``violation`` breaks, by name, with its unit: "the soft limit on x at 5 mm",
    "the stroke high limit of leg 3 at 60 mm" (found from outside without one)."""
    name = violation.kind.value.replace("_", " ")
    where = f" of leg {violation.leg}" if violation.leg is not None else f" on {violation.axis}" if violation.axis else ""
    limit = repr(float(violation.limit)).removesuffix(".0")  # as set: 12.000001 read "12" at 6 digits
    return f"the {name}{'' if name.endswith('limit') else ' limit'}{where} at {limit}{_unit(violation)}"


def _unit(violation: Violation) -> str:
    """`` mm``, `` deg`` or nothing (a condition number) for ``violation``'s limit."""
    if violation.axis in POSE_AXES:
        return f" {POSE_UNITS[POSE_AXES.index(violation.axis)]}"
    return {ViolationKind.STROKE_LOW: " mm", ViolationKind.STROKE_HIGH: " mm", ViolationKind.BASE_CONE: " deg",
            ViolationKind.PLATFORM_CONE: " deg", ViolationKind.SOFT_TILT: " deg"}.get(violation.kind, "")


def _violations_each(context: PlanningContext, frames: Frames | None, positions: Sequence[Sequence[float]],
                     tolerated: StartExcess | None = None) -> list[list[Violation]]:
    """For each position (mm, rad, in the coordinates of ``frames``), every limit, hardware
    or soft, it breaks further than ``tolerated`` (:func:`~hexactl.control.planning.tolerated_excess`)."""
    home = np.asarray(context.active.home)
    relative: NDArray = relative_poses(frames, np.array(positions, dtype=float), home)
    checks = check_poses(context.active.geometry, pose_mm_rad_to_mm_deg(relative))
    hardware = None if tolerated is None else tolerated.hardware
    broken = checks.broken if hardware is None else checks.broken & ~(checks.excess() <= hardware)
    found = [[checks.violation(n, column) for column in np.flatnonzero(row).tolist()] for n, row in enumerate(broken)]
    if context.soft_limits is not None and context.frames is not None:
        for mine, soft in zip(found, soft_limits_broken(context, relative)):
            mine.extend(v for v in soft if tolerated is None or not tolerated.soft_tolerates(v))
    return found
