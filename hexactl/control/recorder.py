"""The data recorder's loop side: one row of references per recorded cycle, nothing more.

:class:`CycleRecorder` is a part of the :class:`~hexactl.control.core.ControlCore`. A
recording is started by a :class:`~hexactl.control.commands.StartRecording` (at once, or
armed until the next motion starts or a fault latches) and records every ``divisor``-th
cycle until it has ``rows`` rows or a :class:`~hexactl.control.commands.StopRecording`
ends it. After each
cycle the loop calls :meth:`CycleRecorder.capture` with the cycle's lateness and compute
time: a due cycle appends one :data:`Row` of references (no copy, no formatting: the
snapshot's values are immutable) to :attr:`CycleRecorder.rows`, a deque that another
thread empties with ``popleft`` (atomic in CPython: no lock the loop could wait on).
Formatting, forward kinematics of the feedback and the file are the reader's
(:mod:`hexactl.application.recording`), in the API's process.

Rows nobody takes are bounded (:data:`MAX_PENDING_ROWS`): beyond, a due row is counted in
``lost`` instead of growing the deque. Idle, :meth:`capture` costs one attribute check.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import TYPE_CHECKING

from hexactl.control import commands as cmd
from hexactl.control.hardware import FeedbackSnapshot
from hexactl.control.results import ErrorCode
from hexactl.kinematics.axes import RelativeMmRad

if TYPE_CHECKING:  # both import this module
    from hexactl.control.preconditions import Refusal
    from hexactl.control.snapshot import CoreSnapshot

MAX_PENDING_ROWS = 1 << 16
"""Rows waiting to be taken at most (2 min at 500 Hz); beyond, rows are lost and counted."""

Row = tuple[int, int, int, int, int, RelativeMmRad, tuple[float, ...], FeedbackSnapshot | None, str]
"""One recorded cycle: (recording id, cycle, t_ns monotonic, lateness_ns, compute_ns,
commanded pose relative mm/rad, set-points sensor mm, the feedback (None before any),
the active calibration's id)."""


class RecorderPhase(StrEnum):
    IDLE = "idle"  # never started
    ARMED = "armed"  # waiting for the next motion to start
    RECORDING = "recording"
    DONE = "done"  # the last recording ended (``ended`` says how)


class RecordingEnd(StrEnum):
    DURATION = "duration"  # every row requested was recorded (or lost)
    STOPPED = "stopped"  # a StopRecording ended it early


@dataclass(frozen=True, slots=True)
class RecorderState:
    """The recorder as published in the snapshot: recording ``recording`` (its id; 0:
    none yet) named ``name``, ``rows`` recorded of ``rows_requested``, ``lost`` for want
    of room (:data:`MAX_PENDING_ROWS`), ``first_cycle`` the cycle it started in (0 until
    it does), ``ended`` once DONE; ``faulted``: a cycle it recorded was in FAULT or ESTOP
    (before its first row, while armed, does not count)."""

    phase: RecorderPhase = RecorderPhase.IDLE
    recording: int = 0
    name: str = ""
    rows: int = 0
    lost: int = 0
    rows_requested: int = 0
    divisor: int = 1
    first_cycle: int = 0
    ended: RecordingEnd | None = None
    faulted: bool = False

    @property
    def active(self) -> bool:
        return self.phase in (RecorderPhase.ARMED, RecorderPhase.RECORDING)


IDLE = RecorderState()


class CycleRecorder:
    """Records the cycles of one recording at a time. Owned by the loop thread, apart
    from :attr:`rows`, which one reader empties with ``popleft``."""

    def __init__(self) -> None:
        self.rows: deque[Row] = deque()
        self.state = IDLE
        self._active = False  # the one check an idle cycle costs
        self._next_cycle = 0  # the next cycle due
        self._faulted = True  # armed: FAULT or ESTOP in the cycle before (a start in one waits for the next)

    def start(self, command: cmd.StartRecording) -> Refusal:
        """Begin ``command``'s recording (armed with ``on_motion``); refused while one is active."""
        if self.state.active:
            return ErrorCode.BUSY, (f"recording {self.state.name!r} is still {self.state.phase.value}: stop it "
                                    "(record_stop) or wait for it to end")
        self.state = RecorderState(RecorderPhase.ARMED if command.on_motion else RecorderPhase.RECORDING,
                                   command.recording, command.name, rows_requested=command.rows,
                                   divisor=command.divisor)
        self._next_cycle = 0  # from the next captured cycle on
        self._faulted = True
        self._active = True
        return None

    def stop(self, command: cmd.StopRecording) -> Refusal:
        """End the active recording early; refused when none is active."""
        if not self.state.active:
            return ErrorCode.NOT_RECORDING, "no recording is under way: nothing to stop"
        self._end(RecordingEnd.STOPPED)
        return None

    def capture(self, snapshot: CoreSnapshot, lateness_ns: int, compute_ns: int) -> None:
        """After the cycle of ``snapshot``: record it if a recording is due (see module)."""
        if not self._active:
            return
        state = self.state
        cycle = snapshot.cycle
        if state.phase is RecorderPhase.ARMED:
            # A fault latched while armed starts it too: a motion that faults in its first
            # cycle never shows as moving, and its recording stayed armed, empty, its fault
            # unseen (found from outside).
            faulted, self._faulted = self._faulted, snapshot.state in ("fault", "estop")
            if not (_moving(snapshot) or (self._faulted and not faulted)):
                return
            state = self.state = replace(state, phase=RecorderPhase.RECORDING)
        if state.first_cycle == 0:
            self.state = state = replace(state, first_cycle=cycle)
            self._next_cycle = cycle
        if cycle < self._next_cycle:
            return
        self._next_cycle = cycle + state.divisor
        rows, lost = state.rows, state.lost
        if len(self.rows) < MAX_PENDING_ROWS:
            self.rows.append((state.recording, cycle, snapshot.t_ns, lateness_ns, compute_ns, snapshot.pose_command,
                              snapshot.setpoints, snapshot.feedback, snapshot.active.calibration_id))
            rows += 1
        else:
            lost += 1
        # Built whole, not by dataclasses.replace: one call instead of a dozen, every recorded cycle.
        done = rows + lost >= state.rows_requested
        # "fault", "estop": ControlState by value, as _moving compares the motion
        faulted = state.faulted or snapshot.state in ("fault", "estop")
        self.state = RecorderState(RecorderPhase.DONE if done else state.phase, state.recording, state.name, rows, lost,
                                   state.rows_requested, state.divisor, state.first_cycle,
                                   RecordingEnd.DURATION if done else None, faulted)
        self._active = not done

    def take(self, limit: int) -> list[Row]:
        """At most ``limit`` of the rows waiting, oldest first (any thread, one reader)."""
        rows, taken = self.rows, []
        for _ in range(min(limit, len(rows))):
            taken.append(rows.popleft())
        return taken

    def _end(self, how: RecordingEnd) -> None:
        self.state = replace(self.state, phase=RecorderPhase.DONE, ended=how)
        self._active = False


def _moving(snapshot: CoreSnapshot) -> bool:
    """A motion (a move, a sequence) is under way. ``"holding"`` is
    ``MotionState.HOLDING``, compared by value: snapshot.py imports this module."""
    return snapshot.motion != "holding" or snapshot.sequence is not None
