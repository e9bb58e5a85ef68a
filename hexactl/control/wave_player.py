"""Wave playback in the loop: each cycle the planned wave's position.

While a wave plays, :class:`~hexactl.control.motion.Motion` takes each cycle's position
from :meth:`WavePlayer.update` instead of the trajectory generator's update. The player
keeps the generator's state equal to the wave's (position; velocity and acceleration by
central differences of the same positions), so that a stop or an abort mid-wave hands
over to the generator's jerk-limited halt from where the platform is and how it moves.
The last position is the start pose exactly; the generator then rests there.

The player checks no preconditions (the core does) and owns the loop thread's state
only: not thread-safe.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from hexactl.control.trajectory import KinematicState, PoseTrajectory, StepResult
from hexactl.control.wave_planning import WavePlan
from hexactl.control.waves import WavePath


class WavePhase(StrEnum):
    RAMP_IN = "ramp_in"
    STEADY = "steady"
    RAMP_OUT = "ramp_out"
    FINISHED = "finished"  # played to the end: at rest on the start pose
    ABORTED = "aborted"  # by stop or abort: braked to rest wherever that ended
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
    """Plays planned waves on ``trajectory`` (the loop's generator), one at a time."""

    def __init__(self, trajectory: PoseTrajectory) -> None:
        self._trajectory = trajectory
        self._path: WavePath | None = None
        self._k = 0
        self._current = self._next = None  # the positions at cycles k and k + 1
        self.progress: WaveProgress | None = None
        """The playing or last wave's progress; a new object whenever it changes."""

    @property
    def playing(self) -> bool:
        return self._path is not None

    def play(self, plan: WavePlan) -> None:
        """Start ``plan``'s wave (from rest at its start, which the core's epoch check
        guarantees); the generator takes its coordinates."""
        path = self._path = plan.path
        self._trajectory.rebase(path.start, plan.frames)
        self._k = 0
        self._current, self._next = path.start, path.at(1)
        self.progress = WaveProgress(1, path.spec.cycles, WavePhase.RAMP_IN)

    def update(self) -> StepResult:
        """Advance one cycle: the generator's position (and state) is this cycle's; at the
        last the wave ends FINISHED with the generator at rest on the start pose."""
        path = self._path
        assert path is not None, "update while no wave plays"
        k = self._k = self._k + 1
        previous, current = self._current, self._next
        self._current, self._next = current, path.at(k + 1)
        if k >= path.samples:
            self._trajectory.reset(path.start)
            self.end(WavePhase.FINISHED)
            return StepResult.FINISHED
        following, h = self._next, path.period_s
        # list comprehensions: every cycle, and a generator into tuple() costs twice as much
        velocity = tuple([(b - a) / (2.0 * h) for a, b in zip(previous, following)])
        acceleration = tuple([(a - 2.0 * c + b) / (h * h) for a, c, b in zip(previous, current, following)])
        self._trajectory.track(tuple.__new__(KinematicState, (current, velocity, acceleration)), path.start)
        self._publish(k)
        return StepResult.WORKING

    def end(self, phase: WavePhase) -> None:
        """The wave ends as ``phase`` (the caller halts or freezes the generator)."""
        if self._path is None:
            return
        self._path = None
        progress = self.progress
        assert progress is not None
        self.progress = WaveProgress(progress.cycle, progress.cycles, phase)

    def _publish(self, k: int) -> None:
        path, progress = self._path, self.progress
        assert path is not None and progress is not None
        t = k * path.period_s
        phase = (WavePhase.RAMP_IN if t < path.ramp_s else
                 WavePhase.RAMP_OUT if t > path.duration_s - path.ramp_s else WavePhase.STEADY)
        cycle = path.cycle_at(k)
        if cycle != progress.cycle or phase is not progress.phase:
            self.progress = WaveProgress(cycle, progress.cycles, phase)
