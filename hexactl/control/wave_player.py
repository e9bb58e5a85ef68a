"""Wave playback in the loop: each cycle the planned wave's position.

While a wave plays, :class:`~hexactl.control.motion.Motion` takes each cycle's position
from :meth:`WavePlayer.update` instead of the trajectory generator's update. The player
keeps the generator's state equal to the wave's (position; velocity and acceleration by
central differences of the same positions). The last position is the start pose exactly;
the generator then rests there.

A stop or an abort mid-wave (:meth:`WavePlayer.brake`) brakes along the wave's own path:
the wave's time slows from rate 1 to 0 over the plan's
:attr:`~hexactl.control.wave_planning.WavePlan.brake_s` (a quintic smoothstep of the rate,
within the motion limits: :func:`~hexactl.control.wave_planning.brake_time_s`), and the
platform comes to rest on a cycle's position of the path that was validated, so every
limit checked on it holds at rest too, in the wave's frame. A wave has no goal: the
generator's per-axis halt would end off the path, beyond the amplitude on a circle. The
wave's progress says ABORTED from the stop on; the generator is halting
(:attr:`~hexactl.control.trajectory.PoseTrajectory.halting`) until the brake's last cycle.

The player checks no preconditions (the core does) and owns the loop thread's state
only: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from math import ceil

from hexactl.control.results import wave_ended_message
from hexactl.control.trajectory import KinematicState, PoseTrajectory, StepResult
from hexactl.control.wave_planning import WavePlan
from hexactl.control.frames import Coordinates
from hexactl.control.waves import WavePath


class WavePhase(StrEnum):
    RAMP_IN = "ramp_in"
    STEADY = "steady"
    RAMP_OUT = "ramp_out"
    FINISHED = "finished"  # played to the end: at rest on the start pose
    ABORTED = "aborted"  # by stop or abort: braked to rest on the wave's path
    FAULT = "fault"  # by a fault, an E-stop or a disable: frozen


PLAYING = frozenset((WavePhase.RAMP_IN, WavePhase.STEADY, WavePhase.RAMP_OUT))


@dataclass(frozen=True, slots=True)
class WaveProgress:
    """The playing wave (or the last one, once it ended): in its period ``cycle`` (1-based)
    of ``cycles``; ``phase`` ramping in, steady, ramping out, or how it ended."""

    cycle: int
    cycles: int
    phase: WavePhase

    @property
    def playing(self) -> bool:
        return self.phase in PLAYING


class WavePlayer:
    """Plays planned waves on ``trajectory`` (the loop's generator), one at a time; ``log``
    (code, message) records how each ends, ``wave_finished``, ``wave_aborted`` or
    ``wave_fault``, as a sequence's end is (found from outside: a wave's end was in the
    status line only, gone from the events once the next wave began)."""

    def __init__(self, trajectory: PoseTrajectory, log: Callable[[str, str], None]) -> None:
        self._trajectory = trajectory
        self._log = log
        self._path: WavePath | None = None
        self._k = 0
        self._current = self._next = None  # the positions at cycles k and k + 1
        self._brake_s = 0.0
        self._braking = False
        self._brake_from = 0.0  # the wave's time (s) where the brake started
        self._brake_span = 0.0  # the brake's duration T, s (2·n cycles)
        self._brake_steps = 0  # its cycles, 2·n: it ends n cycles of the wave's time later
        self._j = 0  # cycles into the brake
        self._rest = None  # where it ends: the path's position k + n
        self.brake_started = False
        """A brake started since the caller last cleared this (for when it ends: :attr:`remaining_s`)."""
        self.progress: WaveProgress | None = None
        """The playing or last wave's progress; a new object whenever it changes."""

    @property
    def playing(self) -> bool:
        """Playing or braking along the path: :meth:`update` drives the generator."""
        return self._path is not None

    @property
    def braking(self) -> bool:
        return self._path is not None and self._braking

    @property
    def remaining_s(self) -> float:
        """While braking: the time to rest, s."""
        return (self._brake_steps - self._j) * self._trajectory.period_s if self.braking else 0.0

    def play(self, plan: WavePlan) -> None:
        """Start ``plan``'s wave (from rest at its start, which the core's epoch check
        guarantees); the generator takes its coordinates."""
        path = self._path = plan.path
        self._trajectory.rebase(path.start, plan.frames)
        self._k = 0
        self._brake_s, self._braking = plan.brake_s, False
        self._current, self._next = path.start, path.at(1)
        self.progress = WaveProgress(1, path.spec.cycles, WavePhase.RAMP_IN)

    def update(self) -> StepResult:
        """Advance one cycle: the generator's position (and state) is this cycle's; at the
        last the wave ends FINISHED with the generator at rest on the start pose."""
        path = self._path
        assert path is not None, "update while no wave plays"
        if self._braking:
            return self._brake_update(path)
        k = self._k = self._k + 1
        previous, current = self._current, self._next
        self._current, self._next = current, path.at(k + 1)
        if k >= path.samples:
            self._trajectory.reset(path.start)
            self.end(WavePhase.FINISHED)
            return StepResult.FINISHED
        self._track(previous, current, path.period_s, path.start)
        self._publish(k)
        return StepResult.WORKING

    def _track(self, previous: Coordinates, current: Coordinates, h: float, goal: Coordinates | None) -> None:
        """The generator at ``current``, its velocity and acceleration by central differences
        of ``previous``, ``current`` and the next position (cycle period ``h``)."""
        following = self._next
        # list comprehensions: every cycle, and a generator into tuple() costs twice as much
        velocity = tuple([(b - a) / (2.0 * h) for a, b in zip(previous, following)])
        acceleration = tuple([(a - 2.0 * c + b) / (h * h) for a, c, b in zip(previous, current, following)])
        self._trajectory.track(tuple.__new__(KinematicState, (current, velocity, acceleration)), goal)

    def brake(self) -> None:
        """Stop the playing wave (it ends ABORTED now): from the next update, brake to rest
        along its path (see the module docstring). Nothing if not playing or braking already."""
        path = self._path
        if path is None or self._braking:
            return
        h = path.period_s
        n = max(1, ceil(self._brake_s / (2.0 * h) - 1e-9))  # rests on cycle k + n of the path
        self._braking, self.brake_started = True, True
        self._brake_from, self._brake_span, self._brake_steps, self._j = self._k * h, 2 * n * h, 2 * n, 0
        self._rest = path.at(self._k + n)
        self._next = self._brake_at(path, 1)  # _current is cycle k's position, where the brake starts
        self._ended(WavePhase.ABORTED)

    def _brake_at(self, path: WavePath, j: int) -> Coordinates:
        """The brake's position ``j`` cycles in: the path at the wave's time slowed by the
        rate 1 - e(u), u = j / steps (its integral in closed form)."""
        if j >= self._brake_steps:
            return self._rest
        u = j / self._brake_steps
        return path.at_time(self._brake_from + self._brake_span * (u - u * u * u * u * (2.5 + u * (-3.0 + u))))

    def _brake_update(self, path: WavePath) -> StepResult:
        j = self._j = self._j + 1
        previous, current = self._current, self._next
        if j >= self._brake_steps:
            self._trajectory.reset(self._rest)  # at rest on the path's cycle k + n
            self._path, self._braking = None, False
            return StepResult.FINISHED
        self._current, self._next = current, self._brake_at(path, j + 1)
        self._track(previous, current, path.period_s, None)
        return StepResult.WORKING

    def end(self, phase: WavePhase) -> None:
        """The wave ends as ``phase`` (the caller halts or freezes the generator); a brake
        under way ends too (its phase stays ABORTED)."""
        if self._path is None:
            return
        self._path = None
        if self._braking:
            self._braking = False
            return
        self._ended(phase)

    def _ended(self, phase: WavePhase) -> None:
        progress = self.progress
        assert progress is not None
        self.progress = WaveProgress(progress.cycle, progress.cycles, phase)
        self._log(f"wave_{phase.value}", wave_ended_message(phase.value, progress.cycle, progress.cycles))

    def _publish(self, k: int) -> None:
        path, progress = self._path, self.progress
        assert path is not None and progress is not None
        t = k * path.period_s
        phase = (WavePhase.RAMP_IN if t < path.ramp_s else
                 WavePhase.RAMP_OUT if t > path.duration_s - path.ramp_s else WavePhase.STEADY)
        cycle = path.cycle_at(k)
        if cycle != progress.cycle or phase is not progress.phase:
            self.progress = WaveProgress(cycle, progress.cycles, phase)
