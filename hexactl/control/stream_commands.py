"""The facade's pose stream: open and close a stream, and each target made reachable.

A stream's targets are not validated as moves are (a whole path refused or run): each
target whose way from the last target handed to the loop leaves the workspace (the
hardware's limits and the soft limits that every planned path is checked against, asked
of one pose at a time, :func:`~hexactl.control.planning.pose_allowed`, along the straight
line at the path step of moves) is replaced by the last reachable pose on that way, found
by bisection. The platform then slows and stops on the boundary instead of being refused. The loop follows the targets
(:mod:`hexactl.control.stream`) within the stream's limits, its velocity box shaped per
target by :func:`stream_velocity_limits` so that no leg can be asked to move faster than
the planning budget whatever the targets do.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from collections import deque
from dataclasses import dataclass, field
from math import ceil, degrees, isfinite, pi, radians
from operator import add

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.frames import Frame, convert, short_way
from hexactl.kinematics.one_line import is_one_line
from hexactl.control.planning import PlanningContext, pose_allowed
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.stream import HORIZON_S
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.trajectory import MotionLimits
from hexactl.kinematics.axes import RelativeMmDeg, RelativeMmRad, ToolInWorkMmDeg, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import leg_lengths

STREAM_FRAMES = (Frame.ZERO, Frame.WORK)
"""The frames a stream's poses may be in (a tool-frame pose is a relative move, and a
stream's targets are absolute)."""

MAX_TIMEOUT_S = 10.0
"""A stream's longest timeout, s: longer would leave a platform moving towards a target
nobody sends any more. The shortest is :data:`TIMEOUT_MIN_CYCLES` loop periods."""

TIMEOUT_MIN_CYCLES = 3
"""Loop periods a stream's timeout lasts at least: the receiver hands a target over once a
period, so a timeout of about one (5 ms at 250 Hz, found from outside) ended the stream
whenever one sample came a cycle late."""

MAX_SOURCE_LENGTH = 64

MAX_HORIZON_S = 0.25
"""The longest :meth:`_OpenStream.horizon`: targets further apart are not a stream to follow
smoothly, and the platform brakes between them."""

MAX_SAMPLE_GAP_S = 0.1
"""Two requests further apart than this (by their sender's clock) give no velocity."""

VELOCITY_WINDOW_S = 0.08
"""How far back (by the sender's clock) the requests the velocity is fitted to reach, at
least, once the stream is that old. From the request before alone, 2 ms back at 500 Hz,
±1 mm of noise read as ±600 mm/s and swung the platform ±44 mm; a straight difference over
this long lags a changing velocity by half of it (a cue performed worse than planned), a
parabola's slope at the newest does not."""

HOLD_INTERVALS = 1.5
"""How many of a sender's usual times between changes of pose a repeated pose may last and
still be a resent sample of a moving source, from a sender that resends (:meth:`_OpenStream.take`):
longer, it is a stop."""

MIN_SAMPLE_GAP_S = 1e-4
"""Nor two closer than this: no stream is faster than 10 kHz, and a sender's clock
resolution (a time printed to the microsecond) would make a jump look like a huge speed."""

BISECTION_STEPS = 12
"""Halvings of the path step in which the way to a target leaves the workspace: the pose
found lies within 1/4096 of it of the boundary."""


VELOCITY_FLOOR = 0.1
"""The share of each axis's velocity limit that a stream's velocity box keeps before it is
scaled, whatever the direction the stream moves in: room to change course on every axis."""

JOIN_DISTANCE = (20.0, 20.0, 20.0, radians(2.0), radians(2.0), radians(2.0))
"""How close (mm, rad, per axis) a stream's sample must come to the platform for the stream
to be followed at its own velocity; farther (its first samples, a sender that did not move
the platform to its first pose), each sample is a step, joined at rest as a step is. Found
from outside: a first sample 600 mm away, of a stream moving at 300 mm/s the other way, had
the platform lunge at it at the caps, 609 mm/s, aiming ahead along the stream's velocity."""

RATE_STEPS = (1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6)
"""Steps (mm, rad) of the finite differences in :func:`leg_rates`."""


def leg_rates(context: PlanningContext, frames: Frames | None, position: Sequence[float]) -> np.ndarray:
    """(6 axes, 6 legs): how fast each leg's length changes (mm per mm, mm per rad) with each
    coordinate of a stream's ``position`` (relative mm/rad, or the tool's pose in the work
    frame of ``frames``), by forward differences of the plain-float inverse kinematics: in
    the stream's own coordinates, whatever its frames."""
    legs, home = context.active.geometry.legs, context.active.home

    def lengths(coordinates: Sequence[float]) -> list[float]:
        absolute = frames.platform_pose(coordinates) if frames is not None else tuple(map(add, home, coordinates))
        return leg_lengths(legs, absolute)

    base = lengths(position)
    rates = []
    for axis, step in enumerate(RATE_STEPS):
        moved = list(position)
        moved[axis] += step
        rates.append([(after - before) / step for after, before in zip(lengths(moved), base)])
    return np.array(rates)


def stream_velocity_limits(context: PlanningContext, frames: Frames | None, position: Sequence[float],
                           velocity: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """Per-axis velocity limits (mm/s, rad/s) for following a stream that moves at
    ``velocity`` through ``position`` (its coordinates, :func:`leg_rates`): a box shaped
    like |velocity| plus :data:`VELOCITY_FLOOR` of ``caps`` on every axis, made as large as
    keeps every leg within ``context.leg_speed_mm_s`` for any velocity inside it (a leg's
    speed is at most Σ |∂l/∂x_j|·limit_j), and never above ``caps``. So the legs' speed,
    not a worst case over every direction, limits a stream along the way it goes."""
    shape = np.abs(velocity) + VELOCITY_FLOOR * caps
    worst_leg_mm_s = float((np.abs(leg_rates(context, frames, position)) * shape[:, None]).sum(axis=0).max())
    return np.minimum(caps, shape * (context.leg_speed_mm_s / worst_leg_mm_s))


@dataclass
class _OpenStream:
    """What the facade keeps of the stream it opened: its number, the coordinates of its
    targets, its motion limits (mm and rad, per axis: velocity, acceleration, jerk), the
    last target handed to the loop (reachable) and the last request with its sender's
    time (for the velocity)."""

    stream: int
    frames: Frames | None
    context: PlanningContext
    limits: tuple[np.ndarray, np.ndarray, np.ndarray]
    last: np.ndarray
    history: deque = field(default_factory=deque)  # (sent_s, request mm/rad), oldest first, back to the baseline
    replaced: tuple[np.ndarray, np.ndarray] | None = None  # (request, goal): a target held outside is bisected once
    sent_ns: int | None = None  # when the last target handed to the loop arrived (monotonic)
    interval_s: float = 0.0  # between targets sent, smoothed
    joined: bool = False  # a sample came within JOIN_DISTANCE of the platform: followed at its velocity since
    held: tuple[float, tuple[float, ...]] | None = None  # (sent_s, pose as sent): the newest that changed, when it came first
    held_velocity: np.ndarray = field(default_factory=lambda: np.zeros(6))  # the velocity it came with
    change_interval_s: float = 0.0  # between the sender's changes of pose (its source's updates), smoothed
    repeated: bool = False  # a request since the held one repeated it
    resends: bool = False  # the sender moved on after repeating a pose: it resends its source's last pose

    def horizon(self, received_ns: int) -> float:
        """How far ahead the loop aims along the velocity of a target that arrived at
        ``received_ns`` (monotonic), s: :data:`HORIZON_S`, longer when targets reach the
        loop less often (a slow sender, or a receiver held up on a busy host), so that the
        platform keeps moving between them instead of braking at each."""
        if self.sent_ns is not None:
            self.interval_s += 0.2 * ((received_ns - self.sent_ns) / 1e9 - self.interval_s)
        self.sent_ns = received_ns
        return min(MAX_HORIZON_S, max(HORIZON_S, 2.0 * self.interval_s))

    def take(self, sent_s: float, pose_mm_deg: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Where the stream is by the sample ``pose_mm_deg`` sent at ``sent_s`` (s, the
        sender's clock), mm and rad (:meth:`near_last`), and its velocity (:meth:`velocity`),
        the request kept for the velocity.

        A request that repeats the pose before is a stop there: velocity zero. But once the
        sender has shown that it resends its source's last pose until the source updates (a
        60 Hz game sent on at 500 Hz: it moved on after a repeat), a repeat no older than
        :data:`HOLD_INTERVALS` of its usual time between changes stands for that pose moved
        on at its velocity since it came. Each repeat read as a stop had the platform arrive
        at rest at every one: found from outside, such a stream of a 314 mm/s sine was
        followed at 159 mm/s, 348 ms late."""
        # Repeats are told by the pose as sent: converted near the last target, which the
        # resent samples move on, a turned frame's angle near ±180° differed in its last bit
        # (found from outside: such a stream stuttered again).
        requested, pose = self.near_last(pose_mm_deg), tuple(pose_mm_deg)
        held = self.held
        if held is not None and pose == held[1] and sent_s >= held[0]:
            age = sent_s - held[0]
            if age < MIN_SAMPLE_GAP_S:  # the same sample again: the receiver hands the one before along
                return requested, self.held_velocity
            self.repeated = True
            if self.resends and age <= min(MAX_SAMPLE_GAP_S, HOLD_INTERVALS * self.change_interval_s):
                return requested + self.held_velocity * age, self.held_velocity
            velocity = np.zeros(6)
        else:
            velocity = self.velocity(requested, sent_s)
            if held is not None and 0.0 < sent_s - held[0] <= MAX_SAMPLE_GAP_S:
                self.change_interval_s += 0.2 * (sent_s - held[0] - self.change_interval_s)
                self.resends = self.resends or self.repeated
            self.held, self.held_velocity, self.repeated = (sent_s, pose), velocity, False
        self.remember(sent_s, requested)
        return requested, velocity

    def remember(self, sent_s: float, requested: np.ndarray) -> None:
        """Keep the request sent at ``sent_s`` (s, the sender's clock) for the velocity, and
        forget what the velocity needs no more: after a gap all before it, else those older
        than :data:`VELOCITY_WINDOW_S` but the newest of them."""
        history = self.history
        if history and not MIN_SAMPLE_GAP_S <= sent_s - history[-1][0] <= MAX_SAMPLE_GAP_S:
            if sent_s - history[-1][0] < MIN_SAMPLE_GAP_S and sent_s >= history[-1][0]:
                return  # the same instant again: the one kept stands
            history.clear()
        history.append((sent_s, requested))
        while len(history) > 2 and sent_s - history[1][0] >= VELOCITY_WINDOW_S:
            history.popleft()

    def velocity(self, requested: np.ndarray, sent_s: float) -> np.ndarray:
        """The stream's velocity at ``requested`` (mm/s, rad/s), within its limits: the slope
        there of a parabola fitted (least squares) to it and the requests remembered, back to
        :data:`VELOCITY_WINDOW_S` at least; the straight difference with only one before;
        zero after a gap or with none before."""
        history = self.history
        if not history or not MIN_SAMPLE_GAP_S <= sent_s - history[-1][0] <= MAX_SAMPLE_GAP_S:
            return np.zeros(6)
        max_velocity = self.limits[0]
        if len(history) < 2:
            return np.clip((requested - history[-1][1]) / (sent_s - history[-1][0]), -max_velocity, max_velocity)
        # A parabola through the window, its slope at the newest: no lag under a steady acceleration
        times = np.array([t - sent_s for t, _ in history] + [0.0])
        poses = np.array([pose for _, pose in history] + [requested])
        slope = np.polyfit(times, poses, 2)[1]
        return np.clip(slope, -max_velocity, max_velocity)

    def near_last(self, pose_mm_deg: Sequence[float]) -> np.ndarray:
        """A sample (mm, deg) in mm and rad; in the work frame with its angles in
        [-180°, 180°] taken the short way round from the last target (:func:`short_way`):
        a sender holding 180° where the tool reads -180° means no turn at all."""
        requested = _mm_rad(pose_mm_deg)
        return requested if self.frames is None else np.array(short_way(self.last, requested))

    def braking_s(self, velocity: np.ndarray) -> np.ndarray:
        """Per axis, how far braking from ``velocity`` goes, in seconds of it: jerk-limited
        braking covers at most v²/(2a) + v·a/(2j)."""
        _, acceleration, jerk = self.limits
        return np.abs(velocity) / (2 * acceleration) + acceleration / (2 * jerk)


@dataclass(frozen=True, slots=True)
class TargetResult:
    """What became of a target: ``sent`` False when no stream is open; ``clamped`` True
    when it was out of reach and replaced; ``goal`` what the loop got, mm/deg;
    ``dropped`` True when it was sent but dropped on the way, the loop being behind
    (:meth:`~hexactl.control.host.LoopHost.submit`): the next target replaces it;
    ``joining`` the sample's largest distance from the platform, mm and deg, while the
    stream has not come within :data:`JOIN_DISTANCE` of it yet (None once it has)."""

    sent: bool
    clamped: bool = False
    goal: RelativeMmDeg | ToolInWorkMmDeg | None = None
    dropped: bool = False
    joining: tuple[float, float] | None = None


class StreamCommands:
    """The pose stream of one facade: ``snapshot()`` the loop's latest, ``context(snapshot)``
    what a plan depends on, commands queued by ``submitter`` (targets by ``host_submit``,
    unanswered), ``limits`` the stream's (``ControllerConfig.stream``). ``target`` is called by one
    thread at a time (the stream's receiver)."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], context: Callable[[CoreSnapshot], PlanningContext],
                 submitter: CommandSubmitter, host_submit: Callable[[cmd.Command], bool], limits: MotionLimits,
                 rate_hz: float) -> None:
        self._limits = limits
        self._rate_hz = rate_hz
        self._snapshot = snapshot
        self._context = context
        self._submitter = submitter
        self._host_submit = host_submit
        self._open: _OpenStream | None = None

    def open(self, source: str, frame: Frame | str, timeout_s: float, deadline_ns: int | None = None) -> CommandResult:
        """Open a stream from ``source`` of target poses in ``frame`` (zero or work) that
        ends if no target comes for ``timeout_s``. At rest, enabled, all six legs."""
        if problem := _open_problem(source, frame, timeout_s, self._rate_hz):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, problem)
        s = self._snapshot()
        if refusal := preconditions.check_stream(s):
            return CommandResult.failure(*refusal)
        frame = Frame(frame)
        context = self._context(s)
        frames = context.frames if frame is Frame.WORK else None
        start = convert(s.trajectory.position, s.frames, frames, s.active.home)
        velocity, acceleration, jerk = (np.asarray(v) for v in self._limits.in_mm_rad())
        # The box at rest on the start is the same fraction of every axis's limit: that fraction.
        scale = float((stream_velocity_limits(context, frames, start, np.zeros(6), velocity) / velocity).min())
        result = self._submitter.submit(
            lambda t: cmd.OpenStream(t, s.epoch, source, frame.value, frames, start, round(timeout_s * 1e9)),
            "stream open", deadline_ns=deadline_ns, velocity_scale=scale)
        if result.ok:
            stream = result.details["ticket"]
            self._open = _OpenStream(stream, frames, context, (velocity, acceleration, jerk),
                                     np.asarray(start, dtype=float))
            result = CommandResult.success(result.message, stream=stream, **result.details)
        return result

    def close(self) -> CommandResult:
        """End the stream: the platform brakes to rest."""
        self._open = None
        return self._submitter.submit(cmd.CloseStream, "stream closed: braking to rest")

    def target(self, pose_mm_deg: Sequence[float], sequence: int, sent_s: float, received_ns: int,
               before: tuple[Sequence[float], float] | None = None) -> TargetResult:
        """Hand the loop ``pose_mm_deg`` (finite; in the stream's frame, mm and deg), made
        reachable, for the stream this facade opened, with the velocity it moves at (from
        the sample sent before it, ``before`` (pose mm/deg, sent_s) when given, else the
        last one handed here, and the sender's times ``sent_s``, s). Nothing is sent when no
        stream is open or it ended (the loop ignores targets for a stream it ended).

        Two workspace checks in the usual case: for a moving stream, of the way to the aim
        (one sample: a stream's steps are shorter than the path step) and of where the
        platform would come to rest if this were the last target; at rest, or when either is
        out of reach, of the way to the target itself, then without velocity (the loop
        arrives at rest on it), stopped where the way first leaves the workspace. Then the
        velocity box at the goal (:func:`stream_velocity_limits`), which slows a velocity
        the legs cannot keep."""
        stream = self._open
        if stream is None:
            return TargetResult(False)
        ended = self._snapshot().last_stream
        if ended is not None and ended.stream == stream.stream:
            self._open = None
            return TargetResult(False)
        if before is not None:
            stream.take(before[1], before[0])
        horizon_s = stream.horizon(received_ns)
        requested, velocity = stream.take(sent_s, pose_mm_deg)
        running = velocity  # the stream's own, while it is joined: how fast its samples move on
        joining = None if stream.joined else self._joining(stream, requested, running)
        if joining is not None:
            velocity = np.zeros(6)  # a step: arrived at at rest, not aimed ahead along the stream
        clamped = False
        goal = requested + velocity * horizon_s
        # The way on is the last target (checked) → the aim → where braking from it ends. The
        # aim alone is not enough, nor the braking end alone: a sample out of reach whose
        # velocity points back inside has its aim outside and its braking end inside.
        if not velocity.any() or not (self._way_stop(stream, stream.last, goal) is None
                                      and self._ok(stream, goal + velocity * stream.braking_s(velocity))):
            velocity = np.zeros(6)
            goal, clamped = self._reachable(stream, requested)
        max_velocity = stream_velocity_limits(stream.context, stream.frames, goal, velocity, stream.limits[0])
        min_velocity = None
        if joining is not None and running.any():
            max_velocity, min_velocity = _joining_limits(stream, goal, running, max_velocity)
        # Faster than the legs allow along its way: passed slower, its direction kept.
        moving = velocity != 0.0
        if moving.any():
            velocity = velocity * min(1.0, float(np.min(max_velocity[moving] / np.abs(velocity[moving]))))
        coordinates = RelativeMmRad if stream.frames is None else ToolInWorkMmRad
        target = coordinates._make(float(v) for v in goal)
        taken = self._host_submit(cmd.StreamTarget(0, stream.stream, target, tuple(float(v) for v in velocity),  # type: ignore[arg-type]
                                                   tuple(float(v) for v in max_velocity), horizon_s, sequence,  # type: ignore[arg-type]
                                                   received_ns, None if min_velocity is None else  # type: ignore[arg-type]
                                                   tuple(float(v) for v in min_velocity)))
        if taken:  # a target dropped on the way is not the loop's: the next one's way runs from the last it got
            stream.last = goal
        return TargetResult(True, clamped, target.in_degrees(), dropped=not taken, joining=joining)

    def _joining(self, stream: _OpenStream, requested: np.ndarray, running: np.ndarray) -> tuple[float, float] | None:
        """How far ``requested``, of a stream running at ``running``, is from the platform
        (mm, deg: the largest on each kind of axis) while it is beyond :data:`JOIN_DISTANCE`;
        None, and the stream joined, once a sample is within it. A platform that trails a
        running stream, arriving at rest on each sample, stays its braking distance behind:
        that much farther along the stream's way still counts as within (found from outside:
        250 mm/s in x trailed 21 to 35 mm behind and was never joined while it ran)."""
        s = self._snapshot()
        platform = np.asarray(convert(s.trajectory.position, s.frames, stream.frames, s.active.home))
        offset = requested - platform
        offset[3:] = (offset[3:] + pi) % (2 * pi) - pi  # the short way round
        gap = np.abs(offset)
        trailing = offset * running > 0  # the sample ahead of the platform on the stream's way
        if np.all(gap <= JOIN_DISTANCE + np.where(trailing, np.abs(running) * stream.braking_s(running), 0.0)):
            stream.joined = True
            return None
        return float(gap[:3].max()), degrees(float(gap[3:].max()))

    def _reachable(self, stream: _OpenStream, requested: np.ndarray) -> tuple[np.ndarray, bool]:
        """``requested`` if the way to it from the last target is allowed, else where that way
        first leaves the workspace (once per request: a target held there is not walked again)."""
        if stream.replaced is not None and np.array_equal(stream.replaced[0], requested):
            return stream.replaced[1], True
        stop = self._way_stop(stream, stream.last, requested)
        if stop is None:
            return requested, False
        stream.replaced = (requested, stop)
        return stop, True

    def _way_stop(self, stream: _OpenStream, start: np.ndarray, end: np.ndarray) -> np.ndarray | None:
        """None when every pose on the straight way from ``start`` (allowed) to ``end`` is
        allowed, sampled at the path step of moves (the workspace is not convex: two allowed
        ends do not make the way between them allowed); else the farthest allowed pose before
        the first sample that is not, bisected within that step."""
        context = stream.context
        step = end - start
        samples = max(1, ceil(max(float(np.abs(step[:3]).max()) / context.path_step_mm,
                                  float(np.abs(step[3:]).max()) / radians(context.path_step_deg))))
        inside = start
        for sample in range(1, samples + 1):
            outside = start + step * (sample / samples)
            if not self._ok(stream, outside):
                for _ in range(BISECTION_STEPS):
                    middle = (inside + outside) / 2.0
                    if self._ok(stream, middle):
                        inside = middle
                    else:
                        outside = middle
                return inside
            inside = outside
        return None

    @staticmethod
    def _ok(stream: _OpenStream, position: np.ndarray) -> bool:
        context = stream.context
        return pose_allowed(context, convert(position.tolist(), stream.frames, None, context.active.home))


def _joining_limits(stream: _OpenStream, goal: np.ndarray, running: np.ndarray,
                    at_rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The velocity limits (max, min; mm/s, rad/s) towards ``goal``, a sample of a stream
    running at ``running`` that is being joined: along the stream's way on each axis the
    box of a stream at that velocity (:func:`stream_velocity_limits`: its speed and a tenth
    of the caps), against it only ``at_rest``'s, the box of a stream at rest. Found from
    outside: with the box at rest both ways, a stream running away faster than it (a yaw
    of 10°/s starting 8° off) was never joined; with the stream's box both ways, a far
    sample coming towards the platform had it lunge at it."""
    along = np.minimum(stream_velocity_limits(stream.context, stream.frames, goal, running, stream.limits[0]),
                       np.abs(running) + at_rest)
    against = np.minimum(at_rest, along)
    return np.where(running > 0, along, against), -np.where(running < 0, along, against)


def _mm_rad(pose_mm_deg: Sequence[float]) -> np.ndarray:
    return np.array([*pose_mm_deg[:3], *(radians(v) for v in pose_mm_deg[3:])], dtype=float)


def _open_problem(source: object, frame: object, timeout_s: object, rate_hz: float) -> str | None:
    if not isinstance(source, str) or not 0 < len(source) <= MAX_SOURCE_LENGTH or not is_one_line(source):
        return f"a stream's source is a printable name of 1 to {MAX_SOURCE_LENGTH} characters, got {source!r}"
    if frame not in tuple(STREAM_FRAMES):
        return (f"a stream's frame is one of {', '.join(f.value for f in STREAM_FRAMES)} (a stream's targets are "
                f"absolute poses), got {frame!r}")
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, (int, float)) or not isfinite(timeout_s) \
            or not 0 < timeout_s <= MAX_TIMEOUT_S:
        return f"a stream's timeout is a number of seconds in (0, {MAX_TIMEOUT_S:g}], got {timeout_s!r}"
    if timeout_s < (cycles := TIMEOUT_MIN_CYCLES / rate_hz):
        return (f"a stream's timeout of {timeout_s * 1e3:g} ms is shorter than {TIMEOUT_MIN_CYCLES} cycles of this "
                f"{rate_hz:g} Hz loop ({cycles * 1e3:g} ms): it would end the stream whenever one sample came a cycle "
                f"late; give at least {cycles * 1e3:g} ms (100 ms is the default)")
    return None
