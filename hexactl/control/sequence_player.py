"""Sequence playback in the loop: move to each waypoint, dwell, record, go on.

:class:`SequencePlayer` drives the loop's :class:`~hexactl.control.trajectory.PoseTrajectory`
through a planned sequence, one :class:`~hexactl.control.planning.Segment` per waypoint:
MOVING until the generator reports the goal reached, then DWELLING for the segment's
``dwell_s``, then a :class:`~hexactl.control.sequences.DwellRecord` and the next
segment. Pause brakes a move (PAUSING, then PAUSED at rest) or freezes what is left of a
dwell; resume goes on with the rest of the move (planned by the caller from where the
platform stopped) or of the dwell.

Times are monotonic ns. The player checks no preconditions (the core does, with
:mod:`~hexactl.control.preconditions`) and owns the loop thread's state only: not
thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

from hexactl.control.hardware import ACTUATOR_COUNT, FeedbackSnapshot
from hexactl.control.planning import Segment
from hexactl.control.results import ErrorCode
from hexactl.control.sequences import DwellRecord
from hexactl.control.trajectory import PoseTrajectory, StepResult
from hexactl.kinematics.axes import RelativeMmRad


class SequencePhase(StrEnum):
    MOVING = "moving"
    DWELLING = "dwelling"
    PAUSING = "pausing"  # braking after pause, mid-move
    PAUSED = "paused"


@dataclass(frozen=True, slots=True)
class SequenceProgress:
    """The playing sequence: ``waypoint`` 1-based (the one being approached or dwelt
    at) of ``segments``; ``paused_in_move``: a pause interrupted the move."""

    name: str
    waypoint: int
    phase: SequencePhase
    segments: tuple[Segment, ...]
    paused_in_move: bool

    @property
    def total(self) -> int:
        return len(self.segments)

    @property
    def segment(self) -> Segment:
        return self.segments[self.waypoint - 1]

    @property
    def remaining(self) -> tuple[Segment, ...]:
        """The segments after the current one."""
        return self.segments[self.waypoint:]


@dataclass(frozen=True, slots=True)
class SequenceReport:
    """The current or the last sequence: ``status`` playing, finished, aborted or fault."""

    name: str
    status: str
    records: tuple[DwellRecord, ...]


def dwell_record(sequence: str, waypoint: int, t_ns: int, pose_command: RelativeMmRad,
                 pose_measured: RelativeMmRad | None, setpoints: Sequence[float],
                 feedback: FeedbackSnapshot | None) -> DwellRecord:
    """The record at the end of ``waypoint``'s dwell at monotonic ``t_ns``: poses given
    relative mm/rad (recorded in mm/deg), set-points sensor mm, the legs NaN without feedback."""
    return DwellRecord(
        sequence, waypoint, t_ns / 1e9,
        pose_command.in_degrees(), None if pose_measured is None else pose_measured.in_degrees(),
        tuple(setpoints), feedback.positions_mm if feedback else (float("nan"),) * ACTUATOR_COUNT)


def start_segment(trajectory: PoseTrajectory, segment: Segment) -> bool:
    """Head for ``segment``'s goal; False if the generator refuses it from the current
    state, which only a move replacing a running one can meet (see ``move_to``). A
    segment in other coordinates than the generator's starts at rest where its plan put
    it (False while moving: the plan assumed rest)."""
    if segment.frames != trajectory.frames:
        if trajectory.moving or segment.start is None:
            return False
        trajectory.rebase(segment.start, segment.frames)
    return trajectory.move_to(segment.goal, segment.time_scale, segment.velocity_scale)


@dataclass(slots=True)
class _Run:
    name: str
    segments: tuple[Segment, ...]
    index: int  # 0-based: the segment being run
    phase: SequencePhase
    dwell_end_ns: int = 0
    dwell_left_ns: int = 0
    paused_in_move: bool = False


class SequencePlayer:
    """Plays one sequence at a time on ``trajectory``.

    ``record(name, waypoint)`` makes the record at the end of a dwell (the core knows
    the poses and legs); ``log(code, message)`` notes a sequence starting and ending.
    """

    def __init__(self, trajectory: PoseTrajectory, record: Callable[[str, int], DwellRecord],
                 log: Callable[[str, str], None]) -> None:
        self._trajectory = trajectory
        self._record = record
        self._log = log
        self._run: _Run | None = None
        self.progress: SequenceProgress | None = None
        """The playing sequence as published; made when it changes, not every cycle."""
        self.report: SequenceReport | None = None
        """The playing sequence's records so far, or the last sequence's outcome."""

    @property
    def playing(self) -> bool:
        return self._run is not None

    def _changed(self, run: _Run) -> None:
        self.progress = SequenceProgress(run.name, run.index + 1, run.phase, run.segments, run.paused_in_move)

    def play(self, name: str, segments: tuple[Segment, ...]) -> None:
        """Start at the first segment, from where the trajectory is."""
        self._run = run = _Run(name, segments, 0, SequencePhase.MOVING)
        self._changed(run)
        self.report = SequenceReport(name, "playing", ())
        start_segment(self._trajectory, segments[0])
        self._log("sequence_started", f"sequence {name!r}: {len(segments)} waypoints")

    def pause(self, now_ns: int) -> None:
        """Brake a move (PAUSED once at rest, see :meth:`update`) or hold a dwell's rest."""
        run = self._run
        assert run is not None, "pause without a sequence (check_pause refuses it)"
        if run.phase is SequencePhase.MOVING:
            self._trajectory.halt()
            run.phase = SequencePhase.PAUSING
            run.paused_in_move = True
        else:
            run.phase = SequencePhase.PAUSED
            run.paused_in_move = False
            run.dwell_left_ns = max(0, run.dwell_end_ns - now_ns)
        self._changed(run)

    def resume(self, remainder: Segment | None, now_ns: int) -> tuple[ErrorCode, str] | None:
        """Go on with ``remainder`` (the rest of an interrupted move, planned from where
        it stopped) or with the rest of the dwell; the refusal if a move was interrupted
        and ``remainder`` is None."""
        run = self._run
        assert run is not None, "resume without a sequence (check_resume refuses it)"
        if run.paused_in_move:
            if remainder is None:
                return ErrorCode.INVALID_ARGUMENT, "the sequence was paused mid-move: resume needs the rest of the move"
            start_segment(self._trajectory, remainder)
            run.phase = SequencePhase.MOVING
        else:
            run.dwell_end_ns = now_ns + run.dwell_left_ns
            run.phase = SequencePhase.DWELLING
        self._changed(run)
        return None

    def end(self, status: str) -> None:
        """End the playing sequence (if any) as ``status``, keeping its records."""
        run = self._run
        if run is None:
            return
        records = self.report.records if self.report else ()
        self.report = SequenceReport(run.name, status, records)
        self._run = self.progress = None
        self._log(f"sequence_{status}", f"sequence {run.name!r} {status} after {len(records)} of {len(run.segments)} waypoints")

    def update(self, result: StepResult, now_ns: int) -> None:
        """After the trajectory's update of this cycle (``result``): arrive, finish a
        pause, end a dwell (record, next segment or finished)."""
        run = self._run
        if run is None:
            return
        if result is StepResult.FINISHED and run.phase is SequencePhase.MOVING:
            run.phase = SequencePhase.DWELLING
            run.dwell_end_ns = now_ns + round(run.segments[run.index].dwell_s * 1e9)
            self._changed(run)
        if run.phase is SequencePhase.PAUSING and not self._trajectory.moving:
            run.phase = SequencePhase.PAUSED
            self._changed(run)
        if run.phase is SequencePhase.DWELLING and now_ns >= run.dwell_end_ns:
            record = self._record(run.name, run.index + 1)
            assert self.report is not None
            self.report = SequenceReport(run.name, "playing", self.report.records + (record,))
            run.index += 1
            if run.index == len(run.segments):
                self.end("finished")
            else:
                start_segment(self._trajectory, run.segments[run.index])
                run.phase = SequencePhase.MOVING
                self._changed(run)
