"""The data recorder's writer, in the API's process: rows from the loop to a CSV file.

The loop keeps a reference per recorded cycle (:mod:`hexactl.control.recorder`); the rows
reach this process losslessly with the loop's reports (:mod:`hexactl.application.loop_link`).
:class:`Recordings` starts a recording on the loop, takes the rows
(:meth:`~hexactl.control.controller.Controller.take_recorded`), computes the measured pose
by forward kinematics of the feedback on the geometry the row names (warm-started from the
previous solution, else from the commanded pose), converts the poses to the chosen frame
(``zero``: relative to the zero posture; ``work``: the tool's pose in the work frame of
the operator's frames at the start) and appends them to ``NAME.csv.partial`` in the first
data directory. When the loop has ended the recording (its duration reached, or stopped)
and every row has arrived, the file is renamed to ``NAME.csv`` (never over an existing
file) and ``NAME.json`` says what was recorded and how it ended. The files' format is
:mod:`hexactl.adapters.files.recording_file`'s.

One recording at a time. :meth:`Recordings.poll` does the work: a thread calls it
(:meth:`Recordings.start_thread`), or a test in simulated time. On shutdown
(:meth:`Recordings.close`) a recording under way is finished with the rows it has.
"""

from __future__ import annotations

import itertools
import math
import os
import re
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from enum import StrEnum
from pathlib import Path
from typing import Any

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.protocol import MAX_RECORDING_S
from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.adapters.files.recording_file import SIGNALS, RecordedCycle, RecordingFile, RecordingFileError
from hexactl.control.controller import Controller
from hexactl.control.frames import OperatorFrames, convert
from hexactl.control.planning import ActiveGeometry
from hexactl.control.recorder import RecorderPhase, Row
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import lengths_from_readings

POLL_INTERVAL_S = 0.05
"""How often the writer's thread takes the rows that arrived."""

NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


class RecordingFrame(StrEnum):
    ZERO = "zero"  # relative to the zero posture
    WORK = "work"  # the tool's pose in the work frame


class RecordingStart(StrEnum):
    NOW = "now"
    NEXT_MOTION = "next_motion"


class RecordingEnded(StrEnum):
    DURATION = "duration"  # every row requested was recorded
    STOPPED = "stopped"  # record_stop
    SHUTDOWN = "shutdown"  # the service stopped during the recording
    FAULT = "fault"  # the control loop died during the recording
    WRITE_FAILED = "write_failed"  # its file could not be written (a full disk): the loop stops recording


@dataclass(frozen=True, slots=True)
class RecordingRequest:
    """A recording to make: ``name`` (the files' stem), the ``signals`` (of
    :data:`SIGNALS`), ``frame`` of the poses, every ``divisor``-th cycle for ``duration_s``
    s, from ``start``."""

    name: str
    signals: tuple[str, ...] = SIGNALS
    frame: RecordingFrame = RecordingFrame.ZERO
    divisor: int = 1
    duration_s: float = 1.0
    start: RecordingStart = RecordingStart.NOW


@dataclass
class _Open:
    """The recording being written."""

    recording: int
    request: RecordingRequest
    rows_requested: int
    loop_rate_hz: float
    file: RecordingFile
    frames: OperatorFrames
    started_wall_s: float
    started_monotonic_ns: int
    first_t_ns: int | None = None
    first_cycle: int | None = None
    last_cycle: int | None = None
    last_t_ns: int | None = None
    longest_gap_ns: int | None = None
    calibration_id: str | None = None
    received: int = 0
    cycles_missing: int = 0
    faults_seen: bool = False
    warm: dict[str, tuple[float, ...]] = field(default_factory=dict)  # last FK solution per calibration
    work: dict[str, Frames] = field(default_factory=dict)  # the operator's frames per calibration (its zero posture)


class Recordings:
    """The API process's data recorder over ``controller`` (whose loop records), writing to
    the first of ``data``'s directories. Thread-safe: requests and the writer's thread
    share one lock (held while a recording starts, so that no row of it is taken before
    it is known)."""

    def __init__(self, controller: Controller, data: DataDirectories) -> None:
        self._controller = controller
        self._directory = data.directories[0]
        self._lock = threading.Lock()
        self._open: _Open | None = None
        self._geometries: dict[str, ActiveGeometry] = {}
        self._ids = itertools.count(time.monotonic_ns() % (1 << 40) + 1)
        self.last: dict[str, Any] | None = None
        """The side file's content of the last recording finished (None: none yet)."""
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._finished = threading.Condition(self._lock)

    # -- requests ------------------------------------------------------------------------

    def start(self, name: str, signals: Sequence[str] = SIGNALS, frame: str = "zero", divisor: int = 1,
              duration_s: float = 1.0, start: str = "now") -> dict[str, Any]:
        """Start recording ``signals`` (of :data:`SIGNALS`) to ``NAME.csv``, poses in
        ``frame`` (:class:`RecordingFrame`), every ``divisor``-th cycle for ``duration_s``
        s, from ``start`` (:class:`RecordingStart`); the reply's fields. :class:`ApiError`
        ``busy`` while one is under way, ``invalid_request`` for a bad name, signal,
        frame, divisor or duration, ``file_exists`` if one of its files exists, the
        loop's refusal otherwise."""
        try:
            request = RecordingRequest(name, tuple(signals), RecordingFrame(frame), divisor, float(duration_s),
                                       RecordingStart(start))
        except (ValueError, TypeError) as error:
            raise ApiError(ErrorCode.INVALID_REQUEST, f"{error}: frame is zero or work, start now or next_motion") from None
        if found := _request_problem(request):
            field, problem = found
            raise ApiError(ErrorCode.INVALID_REQUEST, f"record: {problem}", [{"field": field, "problem": problem}])
        with self._lock:
            if (current := self._open) is not None:
                raise ApiError(ErrorCode.BUSY, f"recording {current.request.name!r} is under way ({current.received} of "
                               f"{current.rows_requested} rows): stop it (record_stop, hexactl record --stop) or "
                               "wait for it to end")
            config = self._controller.config
            rate = config.loop.rate_hz
            rows = max(1, math.ceil(request.duration_s * rate / request.divisor - 1e-9))
            opened = self._create(request, rows, rate)
            result = self._controller.record(opened.recording, request.name, request.divisor, rows,
                                             request.start is RecordingStart.NEXT_MOTION)
            if not result.ok:
                opened.file.discard()
                raise ApiError(result.error.value if result.error else ErrorCode.INTERNAL_ERROR, result.message)
            self._open = opened
        path = opened.file.path
        return {"message": result.message, "path": str(path), "side_file": str(path.with_suffix(".json")),
                "rows": rows, "rate_hz": rate / request.divisor, "duration": rows * request.divisor / rate}

    def stop(self, timeout_s: float = 10.0) -> dict[str, Any]:
        """End the recording under way early. With the writer's thread running, waits (at
        most ``timeout_s``, then finishes with the rows it has) until its file is finished
        and answers the side file's content; stepped by hand, the file is finished by a
        later :meth:`poll` and the answer is :meth:`state`'s. :class:`ApiError`
        ``not_recording`` if none is under way."""
        with self._lock:
            current = self._open
            if current is None:
                raise ApiError(ErrorCode.NOT_RECORDING, "no recording is under way: nothing to stop")
            result = self._controller.record_stop()
            if not result.ok and result.error is not None and result.error.value != ErrorCode.NOT_RECORDING:
                raise ApiError(result.error.value, result.message)
            if self._thread is None:
                return {"message": f"stopping recording {current.request.name!r}", "state": "writing"}
            deadline = time.monotonic() + timeout_s
            while self._open is current and time.monotonic() < deadline:
                self._finished.wait(POLL_INTERVAL_S)
            if self._open is current:
                self._finish(current, RecordingEnded.STOPPED)
            assert self.last is not None
            return {"message": f"recording {current.request.name!r} stopped", **self.last}

    def state(self) -> dict[str, Any]:
        """The writer's state: ``writing`` with the rows so far, else the last recording's
        side file (``state``: ``done``), or ``idle``."""
        with self._lock:
            if (current := self._open) is not None:
                return {"state": "writing", "name": current.request.name, "path": str(current.file.path),
                        "rows_written": current.received, "rows": current.rows_requested}
            if self.last is not None:
                return {"state": "done", **self.last}
            return {"state": "idle"}

    def reserved(self) -> dict[Path, str]:
        """The files of the recording under way (its CSV, under its final and its partial
        name, and its side file), each with why no other write may take it; none when idle."""
        with self._lock:
            if (current := self._open) is None:
                return {}
            csv_path = Path(os.path.realpath(current.file.path))
            why = f"the recording {current.request.name!r} under way writes it"
            return {path: why for path in (csv_path, csv_path.with_name(f"{csv_path.name}.partial"),
                                           csv_path.with_suffix(".json"))}

    # -- the writer ----------------------------------------------------------------------

    def poll(self) -> None:
        """Take the rows that arrived, write them, finish the file once the recording ended."""
        with self._lock:
            self._poll_locked()

    def start_thread(self) -> None:
        """Poll every :data:`POLL_INTERVAL_S` in a thread of its own until :meth:`close`."""
        self._thread = threading.Thread(target=self._run, name="hexactl-recorder", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Finish a recording under way with the rows it has (``shutdown``); stop the thread."""
        self._closing.set()
        if self._thread is not None:
            self._thread.join(5.0)
        with self._lock:
            self._poll_locked()
            if self._open is not None:
                self._finish(self._open, RecordingEnded.SHUTDOWN)

    def _run(self) -> None:
        while not self._closing.wait(POLL_INTERVAL_S):
            self.poll()

    def _poll_locked(self) -> None:
        rows = self._controller.take_recorded()
        current = self._open
        if current is None:
            return
        snapshot = self._controller.snapshot
        for known in (snapshot.active, snapshot.previous):
            if known is not None:
                self._geometries[known.calibration_id] = known
        if snapshot.recorder.recording == current.recording:  # the loop's word: a cycle recorded was in FAULT or ESTOP
            current.faults_seen |= snapshot.recorder.faulted
        try:
            self._write(current, [row for row in rows if row[0] == current.recording])
        except OSError as error:  # a full disk: end this recording, saying why; the writer stays for the next
            self._controller.record_stop()
            self._finish(current, RecordingEnded.WRITE_FAILED, error)
            return
        state = snapshot.recorder
        if state.recording == current.recording and state.phase is RecorderPhase.DONE \
                and current.received >= state.rows:
            self._finish(current, RecordingEnded(state.ended.value if state.ended else "duration"))
        elif self._controller.status().details.get("loop_failure"):
            self._finish(current, RecordingEnded.FAULT)

    def _write(self, current: _Open, rows: list[Row]) -> None:
        pose_frames = current.request.frame is RecordingFrame.WORK
        measure = "pose_measured" in current.request.signals
        cycles = []
        for _, cycle, t_ns, lateness_ns, compute_ns, pose_command, setpoints, feedback, calibration_id in rows:
            if current.first_t_ns is None:
                current.first_t_ns, current.first_cycle, current.calibration_id = t_ns, cycle, calibration_id
            elif current.last_cycle is not None:
                current.cycles_missing += max(0, (cycle - current.last_cycle) // current.request.divisor - 1)
            if current.last_t_ns is not None:  # a loop held up skips cycles' deadlines, not their numbers
                current.longest_gap_ns = max(current.longest_gap_ns or 0, t_ns - current.last_t_ns)
            current.last_cycle, current.last_t_ns = cycle, t_ns
            active = self._geometries.get(calibration_id)
            frames = None
            if pose_frames and active is not None:
                frames = current.work.get(calibration_id) or current.work.setdefault(
                    calibration_id, current.frames.frames(active.home))
            measured = self._measured(current, active, pose_command, feedback) if measure else None
            cycles.append(RecordedCycle(
                (t_ns - current.first_t_ns) / 1e9, cycle, _shown(pose_command, frames, active, pose_frames),
                _shown(measured, frames, active, pose_frames), setpoints,
                feedback.positions_mm if feedback is not None else None, lateness_ns, compute_ns))
        current.file.append(cycles)  # all or, raising, none: rows_written is what the file holds
        current.received += len(rows)

    def _measured(self, current: _Open, active: ActiveGeometry | None, pose_command: Sequence[float],
                  feedback: Any) -> tuple[float, ...] | None:
        """The pose from ``feedback`` by FK on ``active`` (relative mm/rad), None without."""
        if active is None or feedback is None:
            return None
        lengths = lengths_from_readings(active.geometry.legs, feedback.positions_mm).tolist()
        guess = current.warm.get(active.calibration_id) or active.absolute_from_relative_mm_rad(pose_command)
        config = self._controller.config
        result = forward_kinematics(active.geometry.legs, lengths, guess, config.fk_tolerance_mm, config.fk_max_iterations)
        if not result.ok:
            current.warm.pop(active.calibration_id, None)
            return None
        current.warm[active.calibration_id] = result.pose
        return active.relative_from_absolute_mm_rad(result.pose)

    # -- files ---------------------------------------------------------------------------

    def _create(self, request: RecordingRequest, rows: int, rate: float) -> _Open:
        """The recording's file, new in the first data directory; :class:`ApiError`
        ``file_exists`` naming the file in the way, ``file_not_found`` for the directory,
        ``write_failed`` for a file that cannot be created or written."""
        try:
            file = RecordingFile.create(self._directory, request.name, request.signals)
        except RecordingFileError as error:
            raise ApiError(error.code, error.message) from None
        return _Open(next(self._ids), request, rows, rate, file, self._controller.operator_frames(), time.time(),
                     time.monotonic_ns())

    def _finish(self, current: _Open, ended: RecordingEnded, write_error: OSError | None = None) -> None:
        """Finish the files: the CSV under its final name and the side file (after
        ``write_error``, the CSV under its partial name)."""
        self._open = None
        request, recorder = current.request, self._controller.snapshot.recorder
        first_t_ns = current.first_t_ns
        started_wall = current.started_wall_s + ((first_t_ns - current.started_monotonic_ns) / 1e9
                                                 if first_t_ns is not None else 0.0)
        self.last = current.file.finish({
            "name": request.name, "signals": list(request.signals), "frame": request.frame.value,
            "frames": current.frames.model_dump(mode="json") if request.frame is RecordingFrame.WORK else None,
            "divisor": request.divisor, "loop_rate_hz": current.loop_rate_hz,
            "rate_hz": current.loop_rate_hz / request.divisor, "duration_s": request.duration_s,
            "start": request.start.value, "calibration_id": current.calibration_id,
            "started_utc": datetime.fromtimestamp(started_wall, timezone.utc).isoformat() if first_t_ns else None,
            "started_monotonic_s": first_t_ns / 1e9 if first_t_ns is not None else None,
            "first_cycle": current.first_cycle, "rows_requested": current.rows_requested,
            "rows_written": current.received, "cycles_missing": current.cycles_missing,
            "longest_row_gap_s": current.longest_gap_ns / 1e9 if current.longest_gap_ns is not None else None,
            "rows_lost": recorder.lost if recorder.recording == current.recording else 0, "faults_during": current.faults_seen,
            "ended": ended.value,
        }, write_error)
        self._finished.notify_all()


def _shown(pose: Sequence[float] | None, frames: Frames | None, active: ActiveGeometry | None,
           in_work: bool) -> Sequence[float] | None:
    """A pose (relative mm/rad) as recorded: in the work frame with ``in_work`` (None where
    that frame is not known)."""
    if pose is None or not in_work:
        return pose
    if frames is None or active is None:
        return None
    return convert(pose, None, frames, active.home)


def _request_problem(request: RecordingRequest) -> tuple[str, str] | None:
    """The field at fault and what is wrong with it, or None."""
    if not NAME_PATTERN.match(request.name) or request.name.endswith(".partial"):
        return "name", (f"name {request.name!r}: a bare file name (letters, digits, '.', '_', '-'; up to 100), "
                        "without a directory: the files go to the first data directory")
    if unknown := [s for s in request.signals if s not in SIGNALS]:
        return "signals", f"unknown signals {unknown}: choose among {', '.join(SIGNALS)}"
    if not request.signals:
        return "signals", f"no signals: choose among {', '.join(SIGNALS)}"
    if repeated := sorted({s for s in request.signals if request.signals.count(s) > 1}):
        return "signals", f"signals {', '.join(repeated)} named more than once: name each signal once"
    if isinstance(request.divisor, bool) or not isinstance(request.divisor, int) or request.divisor < 1:
        return "divisor", f"divisor {request.divisor!r}: a whole number ≥ 1 (1: every cycle)"
    if not (0 < request.duration_s <= MAX_RECORDING_S):
        return "duration_s", f"duration_s {request.duration_s!r}: more than 0 and at most {MAX_RECORDING_S:g} s"
    return None
