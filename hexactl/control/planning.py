"""Move planning and validation, in the caller's thread (never in the loop).

A move, or each waypoint of a sequence, becomes a :class:`Segment` only after the whole
path has been checked:

1. the goal (relative mm/deg) is converted, and in leg-lock mode projected onto the
   locked leg's constraint (refused if farther than ``lock_max_correction_mm``);
2. :func:`~hexactl.control.trajectory.preview` computes the very trajectory the loop's
   generator will run, from the generator's current state. From rest, ruckig's phase
   synchronisation makes it the straight line in pose space from the current target
   to the goal; a move that replaces a running one follows ruckig's blend, and that
   blend is what gets checked;
3. it is sampled every loop period; in leg-lock mode each sample is projected by the
   loop's own per-cycle procedure (:func:`track_locked`: warm-started from the previous
   cycle's projection, at most ``lock_cycle_iterations``), so a path the loop could not
   follow is refused here instead of faulting mid-motion; the legs' set-points follow
   by batch IK;
4. if any leg would move faster than ``leg_speed_mm_s`` between two cycles, the move is
   stretched in time (time scale k: every velocity divided by k, path unchanged) until
   none does; a requested ``duration`` is a lower bound;
5. the samples, thinned to one every ``path_step_mm`` / ``path_step_deg``, go through
   :func:`~hexactl.kinematics.workspace.assess_poses` (stroke, joint cones, envelope,
   near-singularity). Any violation refuses the whole move or sequence.

Poses inside the control layer are relative to the zero posture in mm and *radians*
("relative mm/rad"); user-facing ones are relative mm/deg.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from itertools import chain
from math import degrees, isfinite
from operator import add, sub

import numpy as np
from numpy.typing import NDArray
from ruckig import Trajectory

from hexactl.control.bounds import MAX_MOTION_S
from hexactl.control.config import ControllerConfig
from hexactl.control.frames import Coordinates, convert, relative_poses, short_way
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.trajectory import KinematicState, MotionLimits, preview
from hexactl.kinematics.frames import Frames, tools_in_work
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import leg_length_of_reading, sensor_setpoints, sensor_setpoints_batch
from hexactl.kinematics.leg_lock import PROJECTION_MAX_ITERATIONS, LockedLeg, ProjectionResult
from hexactl.kinematics.axes import (
    AbsoluteMmRad,
    RelativeMmDeg,
    RelativeMmRad,
    ToolInWorkMmDeg,
    validate_pose_values,
)
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg
from hexactl.kinematics.soft_limits import SoftLimits
from hexactl.kinematics.workspace import (
    POSE_BOUND_ROUNDING,
    Violation,
    ViolationKind,
    check_poses,
    pose_within_limits,
)


MAX_WAYPOINTS = 500
"""The most waypoints one plan (a sequence) may hold, counted before any planning
(:func:`waypoint_count_problem`). Planning's work grows with the number of waypoints as
well as with the motion (:data:`MAX_MOTION_S` bounds that): each waypoint is a trajectory,
its leg speeds and its path's limits. Measured on the 2-core test machine: 1000 tiny
waypoints plan in 0.8 s idle and 16 s at load 11 (ten busy processes), and the API's
watchdog ends the service when one request takes 120 s (the server's
``DEFAULT_HANDLER_TIMEOUT_S``; a 10,000-waypoint file did). 500 keep a sequence's
per-waypoint work near 8 s at that load, about a fifteenth of the watchdog; what the
motion itself costs is bounded by :data:`PLANNING_BUDGET_S`."""

PLANNING_BUDGET_S = 60.0
"""The longest one plan may take, s, checked between waypoints and between batches of
samples (a fraction of a second apart idle): :data:`MAX_WAYPOINTS` and :data:`MAX_MOTION_S`
keep a plan to seconds on an idle core, but a loaded machine runs it ten to twenty times
slower. Half the API's watchdog (120 s), which would end the service.
Refused with ``planning_failed``, naming where planning was: split the sequence."""

MAX_DWELL_S = 86_400.0
"""The longest dwell at a waypoint, s (a day): dwells cost no planning, but a sequence's
duration must stay a number."""

_CHECK_BATCH = 4096  # poses checked per call of check_poses: its cost per call is amortised, its memory bounded

_BUDGET_CYCLES = 4096  # leg-lock samples between two looks at the planning budget (a fraction of a second idle)

_clock = time.monotonic  # the planning budget's clock (tests replace it)

_MAX_STRETCH_ATTEMPTS = 4  # leg speeds scale exactly as 1/k: one stretch normally suffices
_STRETCH_MARGIN = 1.001  # covers the rounding of durations to whole periods
_DURATION_TOLERANCE_S = 1e-6  # a move's duration may fall short of the one asked for by this much
_SCALE_TOLERANCE = 1e-4  # the velocity scale slowing a move under way to its duration: found to this fraction of it


@dataclass(frozen=True, slots=True, eq=False)
class ActiveGeometry:
    """A geometry as the loop uses it, with its identity. ``home``: the zero posture,
    absolute mm/rad; ``stroke``: sensor range, mm. Built in the caller's thread and
    handed to the loop whole: the loop swaps one reference, never edits one."""

    geometry: Geometry
    calibration_id: str
    source: str
    home: AbsoluteMmRad
    stroke: tuple[float, float]

    @classmethod
    def of(cls, geometry: Geometry, calibration_id: str, source: str = "") -> ActiveGeometry:
        return cls(geometry, calibration_id, source, geometry.home.in_radians(), geometry.limits.stroke)

    def absolute_from_relative_mm_rad(self, relative: Sequence[float]) -> AbsoluteMmRad:
        """The absolute pose of ``relative`` (relative mm/rad; a sequence where the loop or
        numpy hands one over)."""
        # The loop calls this several times a cycle: tuple.__new__ over a C-level map, not
        # _make (a Python call and a count check) over a generator.
        return tuple.__new__(AbsoluteMmRad, map(add, self.home, relative))

    def setpoints_at(self, relative: Sequence[float]) -> list[float]:
        """The legs' sensor set-points (mm) that put the platform at ``relative`` (relative
        mm/rad) by this geometry."""
        return sensor_setpoints(self.geometry.legs, self.absolute_from_relative_mm_rad(relative))

    def relative_from_absolute_mm_rad(self, absolute: Sequence[float]) -> RelativeMmRad:
        """The pose relative to this zero posture of ``absolute`` (absolute mm/rad)."""
        return tuple.__new__(RelativeMmRad, map(sub, absolute, self.home))  # as above


@dataclass(frozen=True, slots=True)
class LegLock:
    """Leg ``leg`` (1–6) is braked at sensor reading ``sensor_mm``."""

    leg: int
    sensor_mm: float

    def length_mm(self, geometry: Geometry) -> float:
        """The locked joint-to-joint length in ``geometry``."""
        return leg_length_of_reading(geometry.legs, self.leg - 1, self.sensor_mm)


@dataclass(frozen=True, slots=True)
class Waypoint:
    """A requested target: ``pose`` relative mm/deg, or the tool's pose in the work frame
    (its type says which; any other sequence of six numbers is relative); ``duration_s`` a
    lower bound on the move's duration; ``speed`` (0, 1] scales the velocity limits;
    ``dwell_s`` the time to stay on arrival (sequences)."""

    pose: RelativeMmDeg | ToolInWorkMmDeg
    duration_s: float | None = None
    speed: float | None = None
    dwell_s: float = 0.0


@dataclass(frozen=True, slots=True)
class Segment:
    """One planned move, ready for the loop. ``goal`` in the coordinates of ``frames``
    (None: relative mm/rad, on the constraint in leg-lock mode; else the tool's pose in
    the work frame, mm/rad); ``time_scale``/``velocity_scale`` as in
    :func:`~hexactl.control.trajectory.configure_input`; ``duration_s`` as planned;
    ``start``: where it starts at rest, in its coordinates, when the motion before it ran
    in others (None: it continues from the generator's state)."""

    goal: Coordinates
    time_scale: float
    velocity_scale: float
    dwell_s: float
    duration_s: float
    frames: Frames | None = None
    start: Coordinates | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class PathViolation(Violation):
    """A :class:`~hexactl.kinematics.workspace.Violation` at the first sample of waypoint
    ``waypoint`` (1-based)'s path that violates it; ``pose`` relative mm/deg."""

    waypoint: int
    pose: RelativeMmDeg


@dataclass(frozen=True, slots=True)
class Refusal:
    """Why a plan was refused: ``message`` for people, ``details`` machine-readable extras."""

    code: ErrorCode
    message: str
    violations: tuple[PathViolation, ...] = ()
    details: dict = field(default_factory=dict)

    def result(self) -> CommandResult:
        """The refusal as a command's result: its code, message, violations and details."""
        return CommandResult.failure(self.code, self.message, violations=[asdict(v) for v in self.violations],
                                     **self.details)


@dataclass(frozen=True, slots=True)
class PlanningContext:
    """Everything a plan depends on. ``leg_speed_mm_s``: the budget plans keep the legs
    under (the loop's guard enforces the full ``leg_velocity_mm_s``);
    ``lock_cycle_iterations``: the loop's (``ControllerConfig.lock_cycle_iterations``);
    ``frames``: the operator's (:meth:`~hexactl.control.frames.OperatorFrames.frames`), for
    waypoints in the work frame and the ``soft_limits``."""

    active: ActiveGeometry
    limits: MotionLimits
    period_s: float
    leg_speed_mm_s: float
    lock: LegLock | None = None
    lock_max_correction_mm: float = 25.0
    path_step_mm: float = 2.0
    path_step_deg: float = 0.1
    lock_cycle_iterations: int = ControllerConfig.model_fields["lock_cycle_iterations"].default
    frames: Frames | None = None
    soft_limits: SoftLimits | None = None


@dataclass(frozen=True, slots=True)
class Plan:
    """Either ``segments`` (all validated) or a ``refusal``. In leg-lock mode
    ``lock_corrections_mm`` holds how far each waypoint's goal was moved to keep the locked
    leg's length (the projection's metric distance, mm; empty outside leg-lock mode)."""

    segments: tuple[Segment, ...] = ()
    refusal: Refusal | None = None
    lock_corrections_mm: tuple[float, ...] = ()

    @property
    def ok(self) -> bool:
        return self.refusal is None


def waypoint_count_problem(count: int) -> str | None:
    """What is wrong with a plan (a sequence) of ``count`` waypoints, or None: more than
    :data:`MAX_WAYPOINTS` (checked before any planning)."""
    if count <= MAX_WAYPOINTS:
        return None
    return (f"{count} waypoints: a sequence may have at most {MAX_WAYPOINTS} (planning time grows with each "
            f"waypoint): split it into sequences of at most {MAX_WAYPOINTS} waypoints")


class PlanningBudget:
    """The time one plan may still take (:data:`PLANNING_BUDGET_S` from its creation, by
    ``_clock``); :meth:`refusal` once it is spent."""

    def __init__(self, budget_s: float | None = None) -> None:
        self.budget_s = PLANNING_BUDGET_S if budget_s is None else budget_s
        self._deadline = _clock() + self.budget_s

    def spent(self) -> bool:
        """Whether the time is up."""
        return _clock() > self._deadline

    def refusal(self, where: str, remedy: str) -> Refusal | None:
        """None while time is left; else the refusal, saying ``where`` planning was and the
        ``remedy``."""
        if not self.spent():
            return None
        return Refusal(ErrorCode.PLANNING_FAILED, f"planning took longer than {self.budget_s:g} s, {where}: {remedy} "
                       "(the machine may be busy)", details={"budget_s": self.budget_s})


def plan_path(context: PlanningContext, start: KinematicState, waypoints: Sequence[Waypoint],
              start_frames: Frames | None = None) -> Plan:
    """Plan and validate moves through ``waypoints`` from the generator state ``start``,
    in the coordinates of ``start_frames`` (None: relative mm/rad). Each waypoint after the
    first starts at rest on the previous one; one in other coordinates than the motion
    before it starts from rest (refused while moving). Never raises for bad input: it is
    refused. More than :data:`MAX_WAYPOINTS` are refused before any planning, and a plan
    that takes longer than :data:`PLANNING_BUDGET_S` is refused."""
    total = len(waypoints)
    if problem := waypoint_count_problem(total):
        return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, problem,
                                    details={"waypoints": total, "limit": MAX_WAYPOINTS}))
    budget = PlanningBudget()
    remedy = "split it into shorter sequences" if total > 1 else "split the move"
    at = _waypoint_label(total)
    origin, origin_frames = start.position, start_frames
    segments = []
    home = context.active.home
    checks = _PathChecks(context, relative_poses(start_frames, np.array([origin], dtype=float), home)[0])
    motion_s = 0.0  # the segments' durations so far
    corrections = []
    for number, waypoint in enumerate(waypoints, start=1):
        if refusal := budget.refusal(f"at waypoint {number} of {total}", remedy):
            return Plan(refusal=refusal)
        problem = _check_waypoint(waypoint)
        if problem:
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, f"{at(number)}{problem}", details={"waypoint": number}))
        goal = _goal(context, waypoint.pose)
        if isinstance(goal, Refusal):
            return Plan(refusal=Refusal(goal.code, f"{at(number)}{goal.message}", details={"waypoint": number, **goal.details}))
        goal, frames, correction_mm = goal
        if correction_mm is not None:
            corrections.append(correction_mm)
        rebased = None
        if frames != start_frames:
            if not start.resting:
                return Plan(refusal=Refusal(ErrorCode.BUSY, f"{at(number)}the motion under way runs in another "
                                            "frame: stop first, or move in its frame", details={"waypoint": number}))
            rebased = convert(start.position, start_frames, frames, home)
            start, start_frames = KinematicState.at_rest(rebased), frames
        if frames is not None:
            goal = short_way(start.position, goal)
        # The goal alone first: cheap, and no trajectory is previewed towards a goal
        # that is out of reach anyway (ruckig raises on absurd ones). The one-pose check
        # in plain floats screens it; the full assessment names what a refused goal breaks,
        # and an accepted goal is assessed with its path below.
        goal_relative = relative_poses(frames, np.array([goal], dtype=float), home)
        if not pose_allowed(context, goal_relative[0]):
            goal_violations = path_violations(context, goal_relative, number,
                                              checks.tolerated if number == 1 else None)
            if goal_violations:
                return Plan(refusal=_path_refusal(context, goal_violations, origin, origin_frames, at))
        planned = _plan_segment(context, start, goal, frames, waypoint, MAX_MOTION_S - motion_s, budget, remedy)
        if isinstance(planned, Refusal):
            return Plan(refusal=Refusal(planned.code, f"{at(number)}{planned.message}",
                                        details={"waypoint": number, **planned.details}))
        segment, samples = planned
        checks.add(samples, number)
        if not np.array_equal(samples[-1], goal_relative[0]):
            checks.add(goal_relative, number)  # the goal is checked even where the last sample is not it
        if refusal := checks.flush(budget, lambda: f"checking the paths up to waypoint {number} of {total}", remedy):
            return Plan(refusal=refusal)
        segments.append(replace(segment, start=rebased))
        motion_s += segment.duration_s
        start = KinematicState.at_rest(goal)
    if refusal := checks.flush(budget, lambda: f"checking the paths of {total} waypoints", remedy, final=True):
        return Plan(refusal=refusal)
    if violations := checks.violations():
        return Plan(refusal=_path_refusal(context, violations, origin, origin_frames, at))
    return Plan(segments=tuple(segments), lock_corrections_mm=tuple(corrections))


def _waypoint_label(total: int) -> Callable[[int], str]:
    """How a refusal names the waypoint at fault among ``total``: not at all for a single
    move, where "waypoint 1" would name a sequence the operator never wrote."""
    return (lambda number: f"waypoint {number}: ") if total > 1 else (lambda number: "")


def _path_refusal(context: PlanningContext, violations: Sequence[PathViolation], origin: Coordinates,
                  origin_frames: Frames | None, at: Callable[[int], str]) -> Refusal:
    """The refusal of a plan for ``violations``, saying so when the motion starts outside
    the soft limits (at ``origin``, in the coordinates of ``origin_frames``); ``at`` names
    a waypoint (:func:`_waypoint_label`)."""
    # The pose's axes first, in the message and the list: the legs' limits a pose beyond its
    # envelope breaks follow from it (found from outside: yaw −90° came last, after twelve leg lines).
    violations = sorted(violations, key=lambda violation: violation.kind not in _POSE_KINDS)
    message = _summary(violations, at)
    if outside_soft_limits(context, origin, origin_frames):
        message += f": {OUTSIDE_SOFT_LIMITS}"
    return Refusal(ErrorCode.PATH_VIOLATION, message, tuple(violations))


OUTSIDE_SOFT_LIMITS = ("the platform is outside the soft limits already (held a hair beyond one it was brought to, "
                       "or they were restored at start-up around another pose): a motion may go back inside them, "
                       "never further out; to go further, widen them or clear them")


def outside_soft_limits(context: PlanningContext, position: Coordinates, frames: Frames | None) -> bool:
    """Whether ``position`` (in the coordinates of ``frames``) breaks the operator's soft limits."""
    if context.soft_limits is None or context.frames is None:
        return False
    relative = relative_poses(frames, np.array([position], dtype=float), context.active.home)
    return bool(_soft_violations(context, relative, 1))


def budgeted_path_violations(context: PlanningContext, relative: NDArray, waypoint: int, budget: PlanningBudget,
                             where: str, remedy: str) -> list[PathViolation] | Refusal:
    """:func:`path_violations` of a long path (a wave's), assessed in batches with a look
    at ``budget`` between them: the violations, or the budget's refusal (``where`` and
    ``remedy`` for its message)."""
    checks = _PathChecks(context)
    checks.add(relative, waypoint)
    if refusal := checks.flush(budget, lambda: where, remedy, final=True):
        return refusal
    return checks.violations()


def farthest_violation(context: PlanningContext, relative: NDArray) -> Violation | None:
    """Of the limit that (N, 6) relative mm/rad samples of a path break first (as
    :func:`path_violations` reports it, at the first sample beyond it: a hardware limit
    before a soft one), the violation where the path is farthest beyond it; None if none
    is broken. For a refusal that should say how far, not only where: the first sample of a
    wave beyond the envelope was 1.69 mm beyond, and the wave went on to 745 mm."""
    relative_deg = pose_mm_rad_to_mm_deg(relative)
    kept = thinned(relative_deg, context.path_step_mm, context.path_step_deg)
    checks = check_poses(context.active.geometry, relative_deg[kept])
    rows, columns = np.nonzero(checks.broken)
    if len(rows):
        column = int(columns[0])
        excess = np.nan_to_num(checks.excess()[:, column], nan=np.inf)
        return checks.violation(int(np.argmax(excess)), column)
    if context.soft_limits is None or context.frames is None:
        return None
    soft = [violation for broken in soft_limits_broken(context, relative) for violation in broken]
    if not soft:
        return None
    first = soft_bound(soft[0])
    return max((v for v in soft if soft_bound(v) == first), key=lambda v: abs(v.value - v.limit))


@dataclass(frozen=True, slots=True)
class StartExcess:
    """How far a motion may be beyond each limit it starts beyond: as far as the platform
    already is there, to rounding, so that it may go back inside, never further out.
    ``hardware`` per column of :class:`~hexactl.kinematics.workspace.PoseChecks` (None:
    inside every hardware limit); ``soft`` by :func:`soft_bound` of the soft limits it is
    beyond."""

    hardware: NDArray | None
    soft: Mapping[tuple[ViolationKind, str | None, bool], float]

    def soft_tolerates(self, violation: Violation) -> bool:
        """Whether soft limit ``violation`` goes no further beyond than the start, past the
        same bound."""
        allowed = self.soft.get(soft_bound(violation))
        return allowed is not None and abs(violation.value - violation.limit) <= allowed


def soft_bound(violation: Violation) -> tuple[ViolationKind, str | None, bool]:
    """Which soft bound ``violation`` passes: its kind, its axis and whether it is above
    the bound. Not the axis alone: a platform 100 mm below x's lower bound was let 100 mm
    past its upper one (a move blended from the motion under way overshot it by 19 mm)."""
    return violation.kind, violation.axis, violation.value > violation.limit


def tolerated_excess(context: PlanningContext, start: NDArray) -> StartExcess | None:
    """What a motion from relative mm/rad ``start`` may be beyond (:class:`StartExcess`);
    None when it starts inside every limit. The platform ends up beyond one by a hair
    where it was held on it (a jog to a limit, a move to the envelope's bound, a stream
    clamped on a soft limit): enabled again, it holds the pose its quantised readings
    give, and every move from there was refused, the move back included."""
    excess = check_poses(context.active.geometry, pose_mm_rad_to_mm_deg(start[None])).excess()[0]
    beyond = excess > 0
    hardware = np.where(beyond, excess + POSE_BOUND_ROUNDING, 0.0) if beyond.any() else None
    soft = {} if context.soft_limits is None or context.frames is None else {
        soft_bound(violation): abs(violation.value - violation.limit) + POSE_BOUND_ROUNDING
        for violation in soft_limits_broken(context, start[None])[0]}
    return None if hardware is None and not soft else StartExcess(hardware, soft)


class _PathChecks:
    """:func:`path_violations` of the paths of a plan's waypoints, added in order and
    assessed in batches of :data:`_CHECK_BATCH` poses: the same samples, thinned per path as
    :func:`assess_path` does, the same first violation of each kind per waypoint, in the
    same order; without the per-call cost of :func:`~hexactl.kinematics.workspace.check_poses`
    at every waypoint. A path's first sample is the previous path's last when the waypoint
    starts at rest where the one before ended (the same pose, bit for bit): it is assessed
    once, for the earlier waypoint (and where it breaks a limit, the plan is refused all
    the same)."""

    def __init__(self, context: PlanningContext, start: NDArray | None = None) -> None:
        self._context = context
        self.tolerated = None if start is None else tolerated_excess(context, start)
        self._pending: list[NDArray] = []  # thinned relative mm/deg poses not assessed yet
        self._owners: list[NDArray] = []  # their waypoints
        self._count = 0
        self._last: NDArray | None = None  # the last relative mm/rad sample added
        self._hardware: dict[tuple, PathViolation] = {}  # by (waypoint, kind, leg, axis), first found
        self._soft: dict[int, list[PathViolation]] = {}  # the soft limits' by waypoint

    def add(self, relative: NDArray, waypoint: int) -> None:
        """The (N, 6) relative mm/rad samples of waypoint ``waypoint``'s path."""
        context = self._context
        if context.soft_limits is not None and context.frames is not None:
            if soft := _soft_violations(context, relative, waypoint, self.tolerated if waypoint == 1 else None):
                self._soft.setdefault(waypoint, []).extend(soft)
        relative_deg = pose_mm_rad_to_mm_deg(relative)
        keep = thinned(relative_deg, context.path_step_mm, context.path_step_deg)
        if self._last is not None and keep[0] == 0 and np.array_equal(relative[0], self._last):
            keep = keep[1:]
        self._last = relative[-1].copy()
        if len(keep):
            self._pending.append(relative_deg[keep])
            self._owners.append(np.full(len(keep), waypoint))
            self._count += len(keep)

    def flush(self, budget: PlanningBudget, where, remedy: str, final: bool = False) -> Refusal | None:
        """Assess the pending poses once a batch is full (all of them if ``final``), in
        batches, checking ``budget`` between them (``where()`` says where for its refusal)."""
        if not self._count or (self._count < _CHECK_BATCH and not final):
            return None
        poses, owners = np.concatenate(self._pending), np.concatenate(self._owners)
        self._pending, self._owners, self._count = [], [], 0
        geometry = self._context.active.geometry
        for begin in range(0, len(poses), _CHECK_BATCH):
            if begin and (refusal := budget.refusal(where(), remedy)):
                return refusal
            _note_first_violations(geometry, poses[begin:begin + _CHECK_BATCH], owners[begin:begin + _CHECK_BATCH],
                                   self._hardware, None if self.tolerated is None else self.tolerated.hardware)
        return None

    def violations(self) -> list[PathViolation]:
        """Every violation found, by waypoint: the hardware's limits', then the soft limits'
        (as :func:`path_violations` orders them)."""
        by_waypoint: dict[int, list[PathViolation]] = {}
        for (waypoint, *_), violation in self._hardware.items():
            by_waypoint.setdefault(waypoint, []).append(violation)
        for waypoint in self._soft:
            by_waypoint.setdefault(waypoint, [])
        return [violation for waypoint in sorted(by_waypoint)
                for violation in by_waypoint[waypoint] + _first_of_each(self._soft.get(waypoint, []))]


def path_violations(context: PlanningContext, relative: NDArray, waypoint: int,
                    tolerated: StartExcess | None = None) -> list[PathViolation]:
    """The hardware's limits (:func:`assess_path`: stroke, joint cones, envelope,
    near-singularity) and the soft limits broken by (N, 6) relative mm/rad samples of
    waypoint ``waypoint``'s path: what every commanded path is checked against. The soft
    limits but for those ``tolerated`` (a motion's goal from beyond them: a jog back
    inside, slower than its horizon's reach, was refused; the hardware's, never)."""
    found = assess_path(context.active.geometry, relative, waypoint, context.path_step_mm, context.path_step_deg)
    if context.soft_limits is None or context.frames is None:
        return found
    return found + _soft_violations(context, relative, waypoint, tolerated)


def _soft_violations(context: PlanningContext, relative: NDArray, waypoint: int,
                     tolerated: StartExcess | None = None) -> list[PathViolation]:
    """The soft limits broken by every one of (N, 6) relative mm/rad samples (the context
    has soft limits and frames), but for those ``tolerated`` (its path starts beyond them):
    the first of each kind (per axis) with its pose."""
    first: dict[tuple, PathViolation] = {}
    for n, broken in enumerate(soft_limits_broken(context, relative)):
        for violation in broken:
            if tolerated is not None and tolerated.soft_tolerates(violation):
                continue
            first.setdefault((violation.kind, violation.axis), PathViolation(
                violation.kind, violation.value, violation.limit, violation.message, axis=violation.axis,
                waypoint=waypoint, pose=RelativeMmDeg._make(pose_mm_rad_to_mm_deg(relative[n]))))
    return list(first.values())


def soft_limits_broken(context: PlanningContext, relative: NDArray) -> list[list[Violation]]:
    """For each of (N, 6) relative mm/rad poses, the soft limits it breaks (the context has
    soft limits and frames)."""
    limits, frames = context.soft_limits, context.frames
    assert limits is not None and frames is not None
    return limits.violations(pose_mm_rad_to_mm_deg(tools_in_work(frames, relative + np.asarray(context.active.home))))


def _first_of_each(violations: Sequence[PathViolation]) -> list[PathViolation]:
    """The first of each kind (per axis) of ``violations``, in order (one waypoint's soft
    limits, found over several calls of :func:`_soft_violations`)."""
    first: dict[tuple, PathViolation] = {}
    for violation in violations:
        first.setdefault((violation.kind, violation.axis), violation)
    return list(first.values())


def pose_allowed(context: PlanningContext, relative: Sequence[float]) -> bool:
    """Whether :func:`path_violations` finds nothing at one relative mm/rad pose: the same
    limits, in plain floats, stopping at the first broken (a stream's per-target check)."""
    relative_deg = (*relative[:3], *map(degrees, relative[3:]))
    if not pose_within_limits(context.active.geometry, relative_deg):
        return False
    limits, frames = context.soft_limits, context.frames
    if limits is None or frames is None:
        return True
    tool = frames.tool_in_work(tuple(map(add, relative, context.active.home)))
    return limits.allow((*tool[:3], *map(degrees, tool[3:])))


def assess_path(
    geometry: Geometry, samples: NDArray, waypoint: int, step_mm: float, step_deg: float
) -> list[PathViolation]:
    """Check (N, 6) relative mm/rad ``samples`` of a path, thinned to one per ``step_mm``
    of translation or ``step_deg`` of rotation (first and last always kept); the first
    violation of each kind (per leg or axis) with the pose where it happens."""
    relative_deg = pose_mm_rad_to_mm_deg(samples)
    keep = thinned(relative_deg, step_mm, step_deg)
    found: dict[tuple, PathViolation] = {}
    _note_first_violations(geometry, relative_deg[keep], np.full(len(keep), waypoint), found)
    return list(found.values())


def _note_first_violations(geometry: Geometry, poses: NDArray, owners: NDArray, found: dict[tuple, PathViolation],
                           tolerated: NDArray | None = None) -> None:
    """Add to ``found``, by (waypoint, kind, leg, axis), each violation of (N, 6) relative
    mm/deg ``poses`` of waypoints ``owners`` (N,) that is not in it yet, at the first pose
    that has it, in the order of :func:`~hexactl.kinematics.workspace.assess_poses`'
    violations pose by pose. Only a pose that is its waypoint's first to break some limit
    can add one, so only those poses' violations are built. ``tolerated`` (K,): how far
    waypoint 1's poses may be beyond each limit (:func:`tolerated_excess`)."""
    checks = check_poses(geometry, poses)
    broken = checks.broken
    if tolerated is not None:
        broken = broken & ~((owners == 1)[:, None] & (checks.excess() <= tolerated))
    if not broken.any():
        return
    rows, columns = np.nonzero(broken)  # by pose, then in the order of a pose's violations
    _, first = np.unique(owners[rows] * broken.shape[1] + columns, return_index=True)
    for n in np.unique(rows[first]).tolist():
        owner, pose = int(owners[n]), tuple(checks.relative[n].tolist())
        for violation in (checks.violation(n, column) for column in np.flatnonzero(broken[n]).tolist()):
            key = (owner, violation.kind, violation.leg, violation.axis)
            if key not in found:
                found[key] = PathViolation(violation.kind, violation.value, violation.limit, violation.message,
                                           violation.leg, violation.axis, waypoint=owner, pose=pose)


def thinned(relative_deg: NDArray, step_mm: float, step_deg: float) -> NDArray:
    """The indices of (N, 6) relative mm/deg samples kept at one per ``step_mm`` of
    translation or ``step_deg`` of rotation, ascending; the first and the last always."""
    steps = np.abs(np.diff(relative_deg, axis=0))
    progress = np.concatenate(([0.0], np.cumsum(np.maximum(steps[:, :3].max(axis=1) / step_mm, steps[:, 3:].max(axis=1) / step_deg))))
    keep = np.flatnonzero(np.diff(np.floor(progress), prepend=-1.0) > 0)  # ascending, and the first
    return keep if keep[-1] == len(relative_deg) - 1 else np.append(keep, len(relative_deg) - 1)


def piecewise_line(poses: Sequence[Sequence[float]], step_mm: float, step_deg: float) -> NDArray:
    """Samples (relative mm/rad) along the straight lines through ``poses``, at most
    ``step_mm`` / ``step_deg`` apart."""
    points = np.asarray(poses, dtype=float).reshape(-1, 6)
    pieces = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        span = np.abs(b - a)
        count = max(1, int(np.ceil(max(span[:3].max() / step_mm, np.degrees(span[3:].max()) / step_deg))))
        pieces.append(a + np.outer(np.arange(1, count + 1) / count, b - a))
    return np.concatenate(pieces)


def pace_problem(duration_s: object, speed: object) -> str | None:
    """A move's pace is a duration or a speed, not both: what is wrong, or None."""
    return "give a duration or a speed, not both" if duration_s is not None and speed is not None else None


def _check_waypoint(waypoint: Waypoint) -> str | None:
    problem = validate_pose_values(waypoint.pose)
    if problem:
        return problem
    if waypoint.duration_s is not None and not _number_in(waypoint.duration_s, 0.0, MAX_MOTION_S, low_open=True):
        return f"duration must be a positive number of seconds up to {MAX_MOTION_S:g}, got {waypoint.duration_s!r}"
    if waypoint.speed is not None and not _number_in(waypoint.speed, 0.0, 1.0, low_open=True):
        return f"speed is a fraction of the velocity limits in (0, 1], got {waypoint.speed!r}"
    if problem := pace_problem(waypoint.duration_s, waypoint.speed):
        return problem
    if not _number_in(waypoint.dwell_s, 0.0, MAX_DWELL_S):
        return f"dwell must be 0 to {MAX_DWELL_S:g} s, got {waypoint.dwell_s!r}"
    return None


def _number_in(value: object, low: float, high: float, low_open: bool = False) -> bool:
    """``value`` is a finite real number (not a bool) in [low, high] ((low, high] if ``low_open``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return False
    return isfinite(value) and (low < value if low_open else low <= value) and value <= high


def _goal(context: PlanningContext,
          pose_mm_deg: Sequence[float]) -> tuple[Coordinates, Frames | None, float | None] | Refusal:
    """The goal, the frames of its coordinates and, in leg-lock mode, how far it was moved
    (mm, None outside it): a pose in the work frame in the operator's frames, any other
    relative mm/rad; in leg-lock mode projected onto the constraint (relative mm/rad: a
    projected path keeps no pivot)."""
    if isinstance(pose_mm_deg, ToolInWorkMmDeg):
        if context.frames is None:
            return Refusal(ErrorCode.INVALID_ARGUMENT, "a pose in the work frame needs the operator's frames")
        goal, frames = pose_mm_deg.in_radians(), context.frames
        if context.lock is None:
            return goal, frames, None
        goal = convert(goal, frames, None, context.active.home)
    else:
        goal = RelativeMmDeg._make(float(v) for v in pose_mm_deg).in_radians()
        if context.lock is None:
            return goal, None, None
    projected = project_locked(context.active, context.lock, goal)
    if not projected.ok:
        return Refusal(ErrorCode.LOCK_UNREACHABLE, f"no pose with leg {context.lock.leg} at its locked length near the goal "
                       f"({projected.status.name.lower()})")
    if projected.correction > context.lock_max_correction_mm:
        return Refusal(ErrorCode.LOCK_UNREACHABLE,
                       f"the nearest pose with leg {context.lock.leg} at its locked length is {projected.correction:.1f} mm "
                       f"from the goal (limit {context.lock_max_correction_mm:g} mm): ask for a goal nearer that pose "
                       f"(details: nearest_pose), or unlock leg {context.lock.leg} to go there",
                       details={"correction_mm": projected.correction, "limit_mm": context.lock_max_correction_mm,
                                "nearest_pose": list(context.active.relative_from_absolute_mm_rad(projected.pose).in_degrees())})
    return context.active.relative_from_absolute_mm_rad(projected.pose), None, projected.correction


def locked_leg(active: ActiveGeometry, lock: LegLock) -> LockedLeg:
    """``lock``'s constraint in ``active``'s geometry, for :func:`project_locked`."""
    geometry = active.geometry
    return LockedLeg(geometry.legs, lock.leg, lock.length_mm(geometry), geometry.characteristic_length_mm)


def project_locked(active: ActiveGeometry, lock: LegLock, relative: Sequence[float],
                   max_iterations: int = PROJECTION_MAX_ITERATIONS, start: Sequence[float] | None = None,
                   constraint: LockedLeg | None = None) -> ProjectionResult:
    """:func:`~hexactl.kinematics.leg_lock.project_to_locked_leg` of a relative mm/rad
    pose, from ``start`` (relative mm/rad, default the pose); the result's pose is
    absolute. ``constraint``: the two's :func:`locked_leg`, where the caller keeps it for
    many projections."""
    if constraint is None:
        constraint = locked_leg(active, lock)
    return constraint.project(active.absolute_from_relative_mm_rad(relative), max_iterations,
                              None if start is None else active.absolute_from_relative_mm_rad(start))


def track_locked(active: ActiveGeometry, lock: LegLock, target: Sequence[float], previous_target: Sequence[float],
                 previous_projected: Sequence[float], max_iterations: int,
                 constraint: LockedLeg | None = None) -> ProjectionResult:
    """The loop's leg-lock projection of one cycle's ``target``, at most ``max_iterations``;
    ``previous_target`` and ``previous_projected``: the cycle before's target and the pose
    it was projected to (all relative mm/rad); ``constraint`` as for :func:`project_locked`.
    The result's pose is absolute.

    Warm-started at ``target`` corrected as the previous one was: the correction changes
    little from one cycle to the next, so two iterations reach the tolerance (three at the
    fastest moves), however far the path strays from the constraint; from the target
    itself, 30 mm away, four are needed. Planning runs exactly this over every cycle of a
    move, so the loop can follow whatever it accepted."""
    start = [t + p - q for t, p, q in zip(target, previous_projected, previous_target)]
    return project_locked(active, lock, target, max_iterations, start, constraint)


def _plan_segment(context: PlanningContext, start: KinematicState, goal: Coordinates, frames: Frames | None,
                  waypoint: Waypoint, motion_left_s: float, budget: PlanningBudget | None = None,
                  remedy: str = "split the move") -> tuple[Segment, NDArray] | Refusal:
    """The segment to ``goal`` (in the coordinates of ``frames``, as ``start``) and its
    samples (relative mm/rad); refused before sampling when it would move for longer than
    ``motion_left_s`` (what :data:`MAX_MOTION_S` leaves of the plan), and when ``budget``
    runs out while sampling in leg-lock mode (``remedy`` for its message)."""
    velocity_scale = waypoint.speed or 1.0
    natural = preview(context.limits, context.period_s, start, goal, 1.0, velocity_scale)
    if natural is None:
        slow = (f" at speed {velocity_scale:g} of the velocity limits: raise the speed (a move may take at most "
                f"{MAX_MOTION_S:g} s)") if velocity_scale < 1.0 else ""
        return Refusal(ErrorCode.PLANNING_FAILED, f"the trajectory generator refused the move{slow}")
    time_scale = 1.0  # a move to where it already is takes no time, however long it was asked to take
    if waypoint.duration_s and 0 < natural.duration < waypoint.duration_s:
        if start.resting:
            time_scale = waypoint.duration_s / natural.duration
        elif (slowed := _slowed_to(context, start, goal, waypoint.duration_s, velocity_scale, natural.duration)) is None:
            return Refusal(ErrorCode.PLANNING_FAILED, f"the trajectory generator found no move of at least "
                           f"{waypoint.duration_s:g} s from the motion under way: stop first, or give a speed")
        else:
            velocity_scale, natural = slowed
    for attempt in range(_MAX_STRETCH_ATTEMPTS):
        # the natural trajectory is the first attempt's when nothing stretches it
        trajectory = (natural if attempt == 0 and time_scale == 1.0
                      else preview(context.limits, context.period_s, start, goal, time_scale, velocity_scale))
        if trajectory is None:
            return Refusal(ErrorCode.PLANNING_FAILED, f"the trajectory generator refused the move slowed {time_scale:.3g} "
                           "times (for its duration, or the legs' speed): give a shorter duration, or a speed")
        if trajectory.duration > motion_left_s:
            before = (f", after {MAX_MOTION_S - motion_left_s:.6g} s of the moves before it"
                      if motion_left_s < MAX_MOTION_S else "")
            # a stretch's first attempt runs a little short of the duration asked: that is the least it takes
            lasting = max(trajectory.duration, waypoint.duration_s or 0.0)
            return Refusal(ErrorCode.PLANNING_FAILED,
                           f"the move would take {lasting:.6g} s{before}; a move, or a sequence's moves "
                           f"together, may take at most {MAX_MOTION_S:g} s: raise the speed, shorten the duration"
                           + (" or split the sequence" if before else ""))
        if waypoint.duration_s and 0 < trajectory.duration < waypoint.duration_s - _DURATION_TOLERANCE_S:
            # The duration asked for is a minimum, and scaled limits give nearly, not exactly,
            # k times the natural duration (0.08 % short at 60 s): stretch by what is missing.
            time_scale *= waypoint.duration_s / trajectory.duration
            continue
        samples = _samples(context, start, trajectory, frames, budget, remedy)
        if isinstance(samples, Refusal):
            return samples
        peak = _peak_leg_speed(context, samples)
        if peak <= context.leg_speed_mm_s:
            segment = Segment(goal, time_scale, velocity_scale, waypoint.dwell_s, trajectory.duration, frames)
            return segment, samples
        if start.resting:
            time_scale *= peak / context.leg_speed_mm_s * _STRETCH_MARGIN
        else:  # the limits of the brake from the motion under way are kept (see _slowed_to)
            velocity_scale /= peak / context.leg_speed_mm_s * _STRETCH_MARGIN
    return Refusal(ErrorCode.PLANNING_FAILED, f"could not keep the legs under {context.leg_speed_mm_s:g} mm/s")


def _slowed_to(context: PlanningContext, start: KinematicState, goal: Coordinates, duration_s: float,
               velocity_scale: float, natural_s: float) -> tuple[float, Trajectory] | None:
    """From a motion under way: the velocity scale, at most ``velocity_scale``, whose move
    to ``goal`` lasts at least ``duration_s`` (to :data:`_SCALE_TOLERANCE` of it),
    and its trajectory; None if ruckig refuses one. Not a time scale, which stretches a
    move from rest exactly: it divides the acceleration and jerk limits too (by k², k³),
    and braking the motion under way with those ran on for hundreds of millimetres (a 30 s
    move to x = 100 begun at x = 8 moving +x went to x = 405). At full acceleration and
    jerk the move brakes as a move without a duration would, then cruises slower."""
    def lasting(scale: float) -> Trajectory | None:
        return preview(context.limits, context.period_s, start, goal, 1.0, scale)

    high, low = velocity_scale, velocity_scale * natural_s / duration_s  # a cruise lasts 1/scale
    while (found := lasting(low)) is not None and found.duration < duration_s:
        if low < _SCALE_TOLERANCE * velocity_scale * natural_s / MAX_MOTION_S:  # slower than any move may be
            return None
        high, low = low, low / 2
    if found is None:
        return None
    while high - low > _SCALE_TOLERANCE * low:
        middle = (low + high) / 2
        if (trajectory := lasting(middle)) is None:
            return None
        if trajectory.duration >= duration_s:
            low, found = middle, trajectory
        else:
            high = middle
    return low, found


def _samples(context: PlanningContext, start: KinematicState, trajectory, frames: Frames | None,
             budget: PlanningBudget | None = None, remedy: str = "split the move") -> NDArray | Refusal:
    """The start and the position of every cycle of ``trajectory`` (in the coordinates of
    ``frames``) as poses relative mm/rad. In leg-lock mode (relative coordinates):
    projected as the loop will, each cycle's from the one before, starting at the start's
    full projection (where the loop's commanded pose is); refused if the loop's
    iterations would not converge at some cycle, or when ``budget`` runs out (checked
    every :data:`_BUDGET_CYCLES` cycles: a projection per cycle is planning's dearest work)."""
    count = max(1, int(round(trajectory.duration / context.period_s)))
    targets = [start.position] + [trajectory.at_time(k * context.period_s)[0] for k in range(1, count + 1)]
    lock = context.lock
    if lock is None:
        return relative_poses(frames, _pose_array(targets), context.active.home)
    active = context.active
    constraint, iterations = locked_leg(active, lock), context.lock_cycle_iterations
    projected: list[RelativeMmRad] = []
    for cycle, target in enumerate(targets):
        if budget is not None and cycle and cycle % _BUDGET_CYCLES == 0 and (refusal := budget.refusal(
                f"{cycle * context.period_s:.1f} s into the move of {trajectory.duration:.1f} s", remedy)):
            return refusal
        result = (track_locked(active, lock, target, targets[cycle - 1], projected[-1], iterations, constraint)
                  if cycle else project_locked(active, lock, target, constraint=constraint))
        if not result.ok:
            return Refusal(ErrorCode.LOCK_UNREACHABLE,
                           f"the loop cannot keep leg {lock.leg} at its locked length {cycle * context.period_s:.3f} s "
                           f"into the move ({result.status.name.lower()} after {result.iterations} iterations): "
                           "the path strays too far from the constraint; split the move",
                           details={"t_s": cycle * context.period_s})
        projected.append(active.relative_from_absolute_mm_rad(result.pose))
    return _pose_array(projected)


def _pose_array(poses: Sequence[Sequence[float]]) -> NDArray:
    """(N, 6) floats of N poses, through their flat floats: numpy converts a list of
    sequences one by one, several times slower (a path has a pose per cycle)."""
    return np.fromiter(chain.from_iterable(poses), float, 6 * len(poses)).reshape(-1, 6)


def _peak_leg_speed(context: PlanningContext, samples: NDArray) -> float:
    absolute = samples + np.array(context.active.home)
    setpoints = sensor_setpoints_batch(context.active.geometry.legs, absolute)
    if context.lock is not None:
        setpoints[:, context.lock.leg - 1] = context.lock.sensor_mm
    if len(setpoints) < 2:
        return 0.0
    return float(np.max(np.abs(np.diff(setpoints, axis=0)))) / context.period_s


_POSE_KINDS = (ViolationKind.POSE_RANGE, ViolationKind.SOFT_LIMIT, ViolationKind.SOFT_TILT)
"""Violations in the operator's terms (an axis of the pose), named first in a refusal."""


def _summary(violations: Sequence[PathViolation], at: Callable[[int], str]) -> str:
    first = violations[0]
    more = f" (and {len(violations) - 1} more)" if len(violations) > 1 else ""
    return f"{at(first.waypoint)}{first.message}{more}"
