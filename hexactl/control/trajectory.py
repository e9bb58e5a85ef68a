"""Jerk-limited trajectories in pose space, by ruckig.

Planning happens in *pose space*: the six coordinates of the pose relative to the zero
posture (or, for a motion in the work frame, of the tool's pose in it:
:mod:`hexactl.control.frames`), x, y, z in mm and roll, pitch, yaw in rad, each with its
own velocity, acceleration and jerk limit. Why pose space rather than leg space: ruckig's phase
synchronisation then makes every move from rest a straight line in pose space (all
axes share one time profile), which is the path the move validation samples, and the
platform moves the way the user thinks of it. Leg speeds are a consequence of the path:
the planner (:mod:`hexactl.control.planning`) stretches a move whose legs would exceed
their limit, and the loop's set-point guard (:mod:`hexactl.control.guard`) is only the
last safety net.

:class:`PoseTrajectory` is the loop's online generator (one ``update`` per cycle);
:func:`preview` computes the same trajectory offline for the planner, so that what is
validated is what the loop will run. Two things keep them equal:

- A finished move parks on its goal exactly, not on ruckig's last sample (which misses
  it by ~1e-13): the planner starts the next segment of a sequence at rest on the goal,
  and so does the loop, bit for bit.
- Both go through :func:`_calculate`, which works around ruckig 0.19.4 refusing some
  moves between valid poses (see :data:`JERK_RETRY_SCALE`), the same way in both.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from enum import IntEnum
from math import isfinite, radians
from typing import NamedTuple

from pydantic import BaseModel, ConfigDict, field_validator
from ruckig import (
    ControlInterface,
    DurationDiscretization,
    InputParameter,
    OutputParameter,
    Result,
    Ruckig,
    RuckigError,
    Synchronization,
    Trajectory,
)

from hexactl.kinematics.axes import PerAxis, RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.numbers import SixNumbers

DOFS = 6
_ZERO6 = [0.0] * DOFS
_ZERO_AXES: PerAxis = (0.0,) * DOFS  # type: ignore[assignment]

JERK_RETRY_SCALE = 1.0 - 1e-9
"""A move ruckig refuses is calculated once more with every jerk limit scaled by this.

Why: ruckig 0.19.4 fails (an error in its step 1) when one axis travels, rest to rest,
within a few ulps of 2·a³/j², the distance at which the jerk-limited profile just
touches the acceleration limit, between two of its profile cases. With the default
limits (j = 5·a) that distance is a round 40 mm (x, y), 24 mm (z), 2.4° (roll, pitch) or
3.6° (yaw), so a typed move of exactly that much was refused; and one just beside it,
previewed from the exact goal before, could fail in the loop from where the previous move
really ended (``planner_error``). A jerk limit 1e-9 lower moves that distance by 2e-9
(relative: millions of ulps) and the motion by nothing measurable."""


class MotionLimits(BaseModel):
    """Per-axis limits of commanded motion: [x, y, z] in mm/s, mm/s², mm/s³ and
    [roll, pitch, yaw] in deg/s, deg/s², deg/s³."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    max_velocity: SixNumbers = (200.0, 200.0, 100.0, 10.0, 10.0, 15.0)
    max_acceleration: SixNumbers = (500.0, 500.0, 300.0, 30.0, 30.0, 45.0)
    max_jerk: SixNumbers = (2500.0, 2500.0, 1500.0, 150.0, 150.0, 225.0)

    @field_validator("max_velocity", "max_acceleration", "max_jerk")
    @classmethod
    def _positive(cls, values: tuple[float, ...]) -> tuple[float, ...]:
        if not all(v > 0 for v in values):
            raise ValueError("every limit must be positive")
        return values

    def in_mm_rad(self) -> tuple[list[float], list[float], list[float]]:
        """(velocity, acceleration, jerk) limits with angles in rad."""
        return tuple(  # type: ignore[return-value]
            [*values[:3], *(radians(v) for v in values[3:])]
            for values in (self.max_velocity, self.max_acceleration, self.max_jerk)
        )


class KinematicState(NamedTuple):
    """Where a trajectory is (ruckig's current or target state): ``position`` relative
    mm/rad or, for a motion in the work frame, the tool's pose in it (mm/rad);
    ``velocity`` mm/s and rad/s, ``acceleration`` mm/s² and rad/s², per axis."""

    position: RelativeMmRad | ToolInWorkMmRad
    velocity: PerAxis
    acceleration: PerAxis

    @classmethod
    def at_rest(cls, position: RelativeMmRad | ToolInWorkMmRad) -> KinematicState:
        return cls(position, _ZERO_AXES, _ZERO_AXES)

    @property
    def resting(self) -> bool:
        """No velocity and no acceleration (a finished move parks at exactly zero)."""
        return self.velocity == _ZERO_AXES and self.acceleration == _ZERO_AXES


class StepResult(IntEnum):
    """Outcome of :meth:`PoseTrajectory.update`."""

    IDLE = 0  # nothing to do: at rest on the target
    WORKING = 1  # moving
    FINISHED = 2  # reached the target (or zero velocity, when halting) this cycle
    ERROR = 3  # ruckig refused the input: the generator stopped where it was


def configure_input(
    parameters: InputParameter,
    limits: MotionLimits,
    goal: RelativeMmRad | None,
    time_scale: float = 1.0,
    velocity_scale: float = 1.0,
) -> None:
    """Set ``parameters`` for a move to ``goal`` (relative mm/rad) at rest, or for a halt
    (``goal`` None: velocity interface, target velocity zero). Current state untouched.

    ``velocity_scale`` (0, 1] lowers the velocity limits only. ``time_scale`` k ≥ 1
    stretches the move in time: limits v/k, a/k², j/k³ give the same path k times
    slower, with every velocity divided by k. This, not ruckig's ``minimum_duration``,
    is how a move gets a duration: with ``minimum_duration`` ruckig gives up phase
    synchronisation and the path leaves the straight line (by 0.7 mm on a 600 mm move).
    """
    velocity, acceleration, jerk = limits.in_mm_rad()
    parameters.max_velocity = [v * velocity_scale / time_scale for v in velocity]
    parameters.min_velocity = None  # a stream's own, while joining it, ends here (follow sets it)
    parameters.max_acceleration = [a / time_scale**2 for a in acceleration]
    parameters.max_jerk = [j / time_scale**3 for j in jerk]
    parameters.synchronization = Synchronization.Phase
    # Durations on the loop's time grid: the move ends exactly on a cycle.
    parameters.duration_discretization = DurationDiscretization.Discrete
    parameters.target_velocity = _ZERO6
    parameters.target_acceleration = _ZERO6
    parameters.minimum_duration = None
    if goal is None:
        parameters.control_interface = ControlInterface.Velocity
    else:
        parameters.control_interface = ControlInterface.Position
        parameters.target_position = list(goal)


class PoseTrajectory:
    """The loop's online trajectory generator in pose space: relative mm/rad, or the
    tool's pose in the work frame of :attr:`frames` (:meth:`rebase`).

    Not thread-safe: owned by the loop. ``update`` is cheap while following a plan and
    many times dearer when a new target forces a recalculation.
    """

    def __init__(self, limits: MotionLimits, period_s: float) -> None:
        self.limits = limits
        self.period_s = period_s
        self._ruckig = Ruckig(DOFS, period_s)
        self._input = InputParameter(DOFS)
        self._output = OutputParameter(DOFS)
        self._step = functools.partial(self._ruckig.update, self._input, self._output)  # made once: update() runs every cycle
        self._resting_check = (Ruckig(DOFS, period_s), InputParameter(DOFS), Trajectory(DOFS))  # _beyond_resting_plan
        self._active = False
        self._passing = False  # heading for a goal to pass at a velocity (a stream's)
        self._passing_limits = limits  # the limits of that goal's plan: its brake's too
        self._to_goal = False  # a move to :attr:`goal`, arriving at rest there (move_to)
        self._stopping = False  # halted, on the move's own stop at its goal (see halt)
        self.frames: Frames | None = None
        self._coordinates: type[RelativeMmRad | ToolInWorkMmRad] = RelativeMmRad
        self.goal: RelativeMmRad | ToolInWorkMmRad | None = None
        self.reset(RelativeMmRad(*_ZERO6))

    @property
    def moving(self) -> bool:
        return self._active

    @property
    def halting(self) -> bool:
        return self._active and (self.goal is None or self._stopping)

    @property
    def position(self) -> RelativeMmRad | ToolInWorkMmRad:
        """The position the next update starts from."""
        return tuple.__new__(self._coordinates, self._input.current_position)  # every cycle: no _make call

    @property
    def replanned(self) -> bool:
        """The last update calculated a new plan (a new goal or a halt)."""
        return self._output.new_calculation

    @property
    def remaining_s(self) -> float:
        """Time left on the plan the last update followed, s. It asks ruckig's trajectory
        object: read it when :attr:`replanned`, not every cycle."""
        output = self._output
        return output.trajectory.duration - output.time

    def state(self) -> KinematicState:
        """The state the next update starts from."""
        parameters = self._input
        # tuple.__new__ for both: built every cycle for the loop's snapshot, and a NamedTuple's
        # __new__ and _make are Python calls.
        return tuple.__new__(KinematicState, (
            tuple.__new__(self._coordinates, parameters.current_position),
            tuple(parameters.current_velocity),
            tuple(parameters.current_acceleration),
        ))

    def reset(self, pose: RelativeMmRad | ToolInWorkMmRad) -> None:
        """At rest at ``pose`` (in the current coordinates), nothing to do."""
        parameters = self._input
        parameters.current_position = list(pose)
        parameters.current_velocity = _ZERO6
        parameters.current_acceleration = _ZERO6
        configure_input(parameters, self.limits, pose)
        self.goal = self._coordinates._make(pose)
        self._active = False
        self._passing = False
        self._to_goal = self._stopping = False

    def rebase(self, pose: RelativeMmRad | ToolInWorkMmRad, frames: Frames | None) -> None:
        """At rest at ``pose`` in new coordinates: relative mm/rad (``frames`` None) or the
        tool's pose in the work frame of ``frames``."""
        self.frames = frames
        self._coordinates = RelativeMmRad if frames is None else ToolInWorkMmRad
        self.reset(pose)

    def track(self, state: KinematicState, goal: RelativeMmRad | ToolInWorkMmRad | None) -> None:
        """Be at ``state`` (in the current coordinates), moving towards ``goal`` (None:
        braking to rest, :attr:`halting`): a path the generator does not compute (a wave)
        drives it, without calling :meth:`update`, so that its state is where that path is
        and how it moves."""
        parameters = self._input
        parameters.current_position = list(state.position)
        parameters.current_velocity = list(state.velocity)
        parameters.current_acceleration = list(state.acceleration)
        self.goal = goal
        self._active = True
        self._to_goal = False

    def move_to(self, goal: RelativeMmRad | ToolInWorkMmRad, time_scale: float = 1.0,
                velocity_scale: float = 1.0) -> bool:
        """Head for ``goal`` (in the current coordinates), arriving at rest; replans from the
        current state, so it may be called while moving. Scales: :func:`configure_input`.

        While moving, False (and the motion goes on unchanged) if ruckig refuses the move
        from here: it was planned from the state of a few cycles ago, and, for one, a
        stretched move's lower acceleration limit may be below the acceleration the
        platform has reached since. Checking costs one more calculation, in the cycle of
        the command only. At rest the state is the one the plan started from."""
        if self._active and preview(self.limits, self.period_s, self.state(), goal, time_scale, velocity_scale) is None:
            return False
        configure_input(self._input, self.limits, goal, time_scale, velocity_scale)
        self.goal = self._coordinates._make(goal)
        self._active = True
        self._passing = False
        self._to_goal, self._stopping = True, False
        return True

    def follow(self, goal: RelativeMmRad | ToolInWorkMmRad, velocity: PerAxis, limits: MotionLimits,
               max_velocity: PerAxis, horizon_s: float, min_velocity: PerAxis | None = None) -> None:
        """Head for ``goal`` (in the current coordinates), passing it at ``velocity`` (mm/s,
        rad/s) in no less than ``horizon_s`` (when moving), from wherever the generator is:
        a stream's target (:mod:`hexactl.control.stream`), under the acceleration and jerk
        of ``limits`` and the per-axis ``max_velocity`` and ``min_velocity`` (mm/s, rad/s;
        None: ``-max_velocity``; ``velocity`` within them). Reached before a newer target
        comes, the generator brakes to rest from there (the stream's receiver checked that
        where that ends is reachable). Unlike
        :meth:`move_to` nothing is previewed here: the next target comes a cycle later.
        :meth:`update` arrives at rest on the goal instead when ruckig refuses to pass it,
        or its plan to pass it would back up or overshoot beyond where arriving at rest
        goes (:func:`_beyond_resting_plan`)."""
        parameters = self._input
        configure_input(parameters, limits, goal)
        self._passing_limits = limits
        parameters.max_velocity = list(max_velocity)
        parameters.min_velocity = None if min_velocity is None else list(min_velocity)
        parameters.target_velocity = list(velocity)
        self._passing = any(velocity)
        parameters.minimum_duration = horizon_s if self._passing else None
        self.goal = self._coordinates._make(goal)
        self._active = True
        self._to_goal = False

    def halt(self, limits: MotionLimits | None = None) -> None:
        """Brake smoothly to rest (acceleration and jerk limited, by ``limits``, default
        the motion's) wherever that ends; but never beyond the goal of a move under way,
        and a brake under way goes on as it is.

        Why: the halt's duration is rounded up to the loop's time grid, and a brake
        stretched by up to a cycle can travel farther than the move's own stop: released
        in its deceleration, a jog onto a soft limit came to rest 0.011 mm past it. The
        move's remaining path was validated (every limit holds on it) and ends at rest on
        its goal, so when braking would carry an axis beyond it, the move goes on instead
        (:attr:`halting` all the same): that stop is the shorter one. A brake planned
        again, under other limits, can be the longer one: a stop sent while a stream
        braked under its own, stronger limits took the platform 351 mm on instead of 95,
        out of the workspace."""
        if not self._active or self._stopping or self.goal is None:
            return
        if self._to_goal and _beyond_goal(self.state(), self.goal, limits or self.limits, self.period_s):
            self._stopping = True
            return
        configure_input(self._input, limits or self.limits, None)
        self.goal = None
        self._passing = self._to_goal = False

    def update(self) -> StepResult:
        """Advance one period; the new position is :attr:`position`."""
        if not self._active:
            return StepResult.IDLE
        # ruckig recalculates only when the input changed since its last calculation: once
        # per new target (twice when the jerk retry is needed), not every cycle.
        result = _calculate(self._input, self._step)
        if result is not None and self._passing and self._output.new_calculation \
                and _beyond_resting_plan(self._input, self._output.trajectory, self._resting_check):
            # the plan to pass the target at its velocity backs up (or overshoots) beyond anything the
            # stream's receiver checked: arrive at rest on it instead (below), as a refused one does
            result = None
        if result is None and self._passing:
            # ruckig refuses some (position, velocity, minimum duration) targets from some
            # states; a stream's next target comes a cycle later: arrive at rest on this one.
            _arrive_at_rest(self._input)
            self._passing = False
            result = _calculate(self._input, self._step)
        if result is None:
            self.reset(self.position)
            return StepResult.ERROR
        self._output.pass_to_input(self._input)
        if result == Result.Finished and self._passing:
            # passed a stream's target with no newer one: brake from there under the
            # stream's limits, which its reachability check assumed (the motion's, weaker,
            # carried a stream 58 mm beyond the workspace)
            self.halt(self._passing_limits)
            return StepResult.WORKING
        if result == Result.Finished:
            # Park so that later updates are no-ops: on the goal itself, where the planner
            # starts the next segment (a halt has no goal: where it ended).
            self.reset(self.goal if self.goal is not None else self.position)
            return StepResult.FINISHED
        return StepResult.WORKING


def _beyond_resting_plan(parameters: InputParameter, plan: Trajectory,
                         check: tuple[Ruckig, InputParameter, Trajectory]) -> bool:
    """Whether ``plan``, just calculated from ``parameters`` to pass their target position at
    their target velocity (a stream's target), goes on some axis beyond both the span from
    its start to the target and where arriving at rest on the target (from the same state,
    under the same limits) would go. ``check`` (a generator, an input and a trajectory)
    calculates that arrival, only when the plan leaves the span.

    Why: ruckig reaches a target velocity it has no room to reach ahead by backing up
    first. A stream's receiver checks the way from its last target to the aim and where
    braking from the aim ends, not such a detour: a stream coming back inside after being
    held at rest on the boundary went 12 mm beyond it (x at 610 mm, aiming inwards at
    320 mm/s, the plan backed up to 634), and a ramp from rest went 3 mm backwards first.
    Arriving at rest on the target goes no further than the span and the generator's own
    braking, as for any target without velocity."""
    start, goal = parameters.current_position, parameters.target_position
    extrema = plan.position_extrema
    tolerance = NEGLIGIBLE[0]
    if all(min(s, g) - tolerance <= e.min and e.max <= max(s, g) + tolerance
           for s, g, e in zip(start, goal, extrema)):
        return False  # the usual case: no calculation more
    generator, resting, trajectory = check
    # A copy of the input as configure_input and the stream's target set it (ruckig's input
    # cannot be copied, and _calculate's retries change the one it is given), then at rest.
    resting.current_position, resting.current_velocity, resting.current_acceleration = (
        start, parameters.current_velocity, parameters.current_acceleration)
    resting.max_velocity, resting.min_velocity, resting.max_acceleration, resting.max_jerk = (
        parameters.max_velocity, parameters.min_velocity, parameters.max_acceleration, parameters.max_jerk)
    resting.synchronization, resting.duration_discretization, resting.control_interface = (
        parameters.synchronization, parameters.duration_discretization, parameters.control_interface)
    resting.target_position = goal
    _arrive_at_rest(resting)
    if _calculate(resting, lambda: generator.calculate(resting, trajectory)) is None:
        return True  # no arrival to compare with: the detour is not allowed
    return any(e.min < min(s, g, r.min) - tolerance or e.max > max(s, g, r.max) + tolerance
               for s, g, e, r in zip(start, goal, extrema, trajectory.position_extrema))


def _arrive_at_rest(parameters: InputParameter) -> None:
    """A target to pass at a velocity (a stream's) made one to arrive at rest on."""
    parameters.target_velocity, parameters.target_acceleration, parameters.minimum_duration = _ZERO6, _ZERO6, None


def _beyond_goal(start: KinematicState, goal: RelativeMmRad | ToolInWorkMmRad | None, limits: MotionLimits,
                 period_s: float) -> bool:
    """Whether a halt from ``start`` under ``limits`` comes to rest farther from
    ``start`` than ``goal`` on some axis (True if ruckig refuses it: the move, not an
    unknown brake)."""
    if goal is None:
        return False
    braking = preview(limits, period_s, start, None)
    if braking is None:
        return True
    rest = braking.at_time(braking.duration)[0]
    return any(abs(r - p) > abs(g - p) for r, p, g in zip(rest, start.position, goal))


def preview(
    limits: MotionLimits,
    period_s: float,
    start: KinematicState,
    goal: RelativeMmRad | None,
    time_scale: float = 1.0,
    velocity_scale: float = 1.0,
) -> Trajectory | None:
    """The trajectory :class:`PoseTrajectory` would run from ``start`` to ``goal`` (None:
    its halt); None if ruckig refuses it."""
    if not all(isfinite(v) for part in (*start, *([goal] if goal is not None else [])) for v in part):
        return None
    parameters = InputParameter(DOFS)
    parameters.current_position, parameters.current_velocity, parameters.current_acceleration = (
        list(part) for part in start
    )
    configure_input(parameters, limits, goal, time_scale, velocity_scale)
    trajectory = Trajectory(DOFS)
    generator = Ruckig(DOFS, period_s)
    return None if _calculate(parameters, lambda: generator.calculate(parameters, trajectory)) is None else trajectory


NEGLIGIBLE = (1e-6, 1e-6, 1e-3)
"""Position (mm, rad), velocity (/s) and acceleration (/s²) of an axis that count as
rounding when they are all this close to its target: :func:`_settle_negligible`."""


def _settle_negligible(parameters: InputParameter) -> bool:
    """Put each axis that is within :data:`NEGLIGIBLE` of its target state exactly on it;
    True if one moved. Why: ruckig 0.19.4 refuses (an error in its step 1) an axis that
    is to travel a few 1e-8 mm at 1e-9 mm/s, as one does whose start came from forward
    kinematics of the feedback and whose target is a round zero (a stream along x alone
    moves y by nothing). Settling it moves the commanded pose by at most a nanometre."""
    position, velocity, acceleration = (list(values) for values in (
        parameters.current_position, parameters.current_velocity, parameters.current_acceleration))
    settled = False
    for axis, (p, v, a, goal, goal_v) in enumerate(zip(position, velocity, acceleration, parameters.target_position,
                                                       parameters.target_velocity)):
        if (p, v, a) != (goal, goal_v, 0.0) and abs(p - goal) <= NEGLIGIBLE[0] and abs(v - goal_v) <= NEGLIGIBLE[1] \
                and abs(a) <= NEGLIGIBLE[2]:
            position[axis], velocity[axis], acceleration[axis] = goal, goal_v, 0.0
            settled = True
    if settled:
        parameters.current_position, parameters.current_velocity, parameters.current_acceleration = (
            position, velocity, acceleration)
    return settled


def _calculate(parameters: InputParameter, calculate: Callable[[], Result]) -> Result | None:
    """``calculate()`` (ruckig on ``parameters``): its result, or None if ruckig refused
    the input even after a retry with the jerk limits scaled by
    :data:`JERK_RETRY_SCALE` and one with the axes that are a rounding away from their
    target settled on it (:func:`_settle_negligible`). The scaled limits stay in ``parameters``: the online
    generator would otherwise see a changed input and recalculate every cycle."""
    for attempt in range(3):
        if attempt == 1:
            parameters.max_jerk = [j * JERK_RETRY_SCALE for j in parameters.max_jerk]
        elif attempt == 2 and not _settle_negligible(parameters):
            break
        try:
            result = calculate()
        except (RuckigError, ValueError):  # raised for some inputs; ValueError: a code the binding lacks (-101)
            continue
        if result == Result.Working or result == Result.Finished:
            return result
    return None
