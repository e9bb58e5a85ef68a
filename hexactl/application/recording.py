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
file) and ``NAME.json`` says what was recorded and how it ended.

One recording at a time. :meth:`Recordings.poll` does the work: a thread calls it
(:meth:`Recordings.start_thread`), or a test in simulated time. On shutdown
(:meth:`Recordings.close`) a recording under way is finished with the rows it has.
"""

from __future__ import annotations

import itertools
import json
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
from typing import Any, TextIO

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.control.controller import Controller
from hexactl.control.frames import OperatorFrames, convert
from hexactl.control.planning import ActiveGeometry
from hexactl.control.recorder import RecorderPhase, Row
from hexactl.control.snapshot import ControlState
from hexactl.kinematics.axes import POSE_AXES
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import lengths_from_readings

SIGNALS = ("pose_command", "pose_measured", "setpoints", "feedback", "lateness", "compute")
"""What a recording may hold, in the order of the CSV's columns (after ``t_s`` and ``cycle``)."""

MAX_DURATION_S = 3600.0
"""The longest recording: an hour is 1.8 million rows (about 0.5 GB) at 500 Hz."""

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


def columns(signals: Sequence[str]) -> list[tuple[str, str]]:
    """The CSV's (column, unit) for ``signals``, in file order."""
    pose_units = ["mm"] * 3 + ["deg"] * 3
    out = [("t_s", "s"), ("cycle", "")]
    for signal in SIGNALS:
        if signal not in signals:
            continue
        if signal in ("pose_command", "pose_measured"):
            out += [(f"{signal}_{axis}_{unit}", unit) for axis, unit in zip(POSE_AXES, pose_units)]
        elif signal == "setpoints":
            out += [(f"setpoint_{leg}_mm", "mm") for leg in range(1, 7)]
        elif signal == "feedback":
            out += [(f"feedback_{leg}_mm", "mm") for leg in range(1, 7)]
        else:
            out.append((f"{signal}_us", "us"))
    return out


@dataclass
class _Open:
    """The recording being written."""

    recording: int
    request: RecordingRequest
    rows_requested: int
    loop_rate_hz: float
    directory: int  # descriptor of the data directory the files go to
    path: Path  # the CSV's final path
    partial: str  # the partial file's name in it
    handle: TextIO
    frames: OperatorFrames
    started_wall_s: float
    started_monotonic_ns: int
    first_t_ns: int | None = None
    first_cycle: int | None = None
    last_cycle: int | None = None
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
        self._data = data
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
        problem = _request_problem(request)
        if problem:
            raise ApiError(ErrorCode.INVALID_REQUEST, problem)
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
                self._discard(opened)
                raise ApiError(result.error.value if result.error else ErrorCode.INTERNAL_ERROR, result.message)
            self._open = opened
            opened.handle.write(",".join(name for name, _ in columns(request.signals)) + "\n")
        return {"message": result.message, "path": str(opened.path), "side_file": str(opened.path.with_suffix(".json")),
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
                return {"state": "writing", "name": current.request.name, "path": str(current.path),
                        "rows_written": current.received, "rows": current.rows_requested}
            if self.last is not None:
                return {"state": "done", **self.last}
            return {"state": "idle"}

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
        current.faults_seen |= snapshot.state in (ControlState.FAULT, ControlState.ESTOP)
        self._write(current, [row for row in rows if row[0] == current.recording])
        state = snapshot.recorder
        if state.recording == current.recording and state.phase is RecorderPhase.DONE \
                and current.received >= state.rows:
            self._finish(current, RecordingEnded(state.ended.value if state.ended else "duration"))
        elif self._controller.status().details.get("loop_failure"):
            self._finish(current, RecordingEnded.FAULT)

    def _write(self, current: _Open, rows: list[Row]) -> None:
        signals = current.request.signals
        pose_frames = current.request.frame is RecordingFrame.WORK
        lines = []
        for _, cycle, t_ns, lateness_ns, compute_ns, pose_command, setpoints, feedback, calibration_id in rows:
            if current.first_t_ns is None:
                current.first_t_ns, current.first_cycle, current.calibration_id = t_ns, cycle, calibration_id
            elif current.last_cycle is not None:
                current.cycles_missing += max(0, (cycle - current.last_cycle) // current.request.divisor - 1)
            current.last_cycle = cycle
            active = self._geometries.get(calibration_id)
            frames = None
            if pose_frames and active is not None:
                frames = current.work.get(calibration_id) or current.work.setdefault(
                    calibration_id, current.frames.frames(active.home))
            cells = [f"{(t_ns - current.first_t_ns) / 1e9:.6f}", str(cycle)]
            if "pose_command" in signals:
                cells += _pose_cells(pose_command, frames, active, pose_frames)
            if "pose_measured" in signals:
                measured = self._measured(current, active, pose_command, feedback)
                cells += _pose_cells(measured, frames, active, pose_frames)
            if "setpoints" in signals:
                cells += [f"{value:.6f}" for value in setpoints]
            if "feedback" in signals:
                cells += [f"{value:.6f}" for value in feedback.positions_mm] if feedback is not None else [""] * 6
            if "lateness" in signals:
                cells.append(f"{lateness_ns / 1e3:.1f}")
            if "compute" in signals:
                cells.append(f"{compute_ns / 1e3:.1f}")
            lines.append(",".join(cells))
        current.received += len(rows)
        if lines:
            current.handle.write("\n".join(lines) + "\n")
            current.handle.flush()

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
        """Open ``NAME.csv.partial`` new in the first data directory (descriptor-relative,
        no symlink followed); :class:`ApiError` ``file_exists`` naming the file in the way."""
        name = request.name
        try:
            directory = os.open(self._directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError as error:
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{self._directory}: cannot open the recordings directory "
                           f"({error.strerror}): create it or start the service with another --data-dir") from None
        try:
            for existing in (f"{name}.csv", f"{name}.json", f"{name}.csv.partial"):
                if _exists(existing, directory):
                    raise ApiError(ErrorCode.FILE_EXISTS, f"{self._directory / existing} exists; a recording never "
                                   "overwrites a file: choose another name or remove that file")
            descriptor = os.open(f"{name}.csv.partial", os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                                 | os.O_CLOEXEC, 0o666, dir_fd=directory)
        except ApiError:
            os.close(directory)
            raise
        except OSError as error:
            os.close(directory)
            raise ApiError(ErrorCode.FILE_NOT_FOUND, f"{self._directory / name}.csv.partial: cannot create it "
                           f"({error.strerror})") from None
        return _Open(next(self._ids), request, rows, rate, directory, self._directory / f"{name}.csv",
                     f"{name}.csv.partial", os.fdopen(descriptor, "w", encoding="utf-8", newline=""),
                     self._controller.operator_frames(), time.time(), time.monotonic_ns())

    def _discard(self, current: _Open) -> None:
        current.handle.close()
        try:
            os.unlink(current.partial, dir_fd=current.directory)
        except OSError:
            pass
        os.close(current.directory)

    def _finish(self, current: _Open, ended: RecordingEnded) -> None:
        """Close the CSV, move it to its final name (never over a file), write the side file."""
        self._open = None
        handle, directory = current.handle, current.directory
        handle.flush()
        os.fsync(handle.fileno())
        handle.close()
        final = current.path.name
        path = current.path
        try:
            # A hard link fails if the target exists: no recording overwrites a file made meanwhile.
            os.link(current.partial, final, src_dir_fd=directory, dst_dir_fd=directory, follow_symlinks=False)
            os.unlink(current.partial, dir_fd=directory)
        except FileExistsError:
            path = self._directory / current.partial  # kept under its partial name, said in the side file
        finally:
            os.close(directory)
        request, recorder = current.request, self._controller.snapshot.recorder
        first_t_ns = current.first_t_ns
        started_wall = current.started_wall_s + ((first_t_ns - current.started_monotonic_ns) / 1e9
                                                 if first_t_ns is not None else 0.0)
        side = {
            "name": request.name, "csv": str(path), "signals": list(request.signals), "frame": request.frame.value,
            "frames": current.frames.model_dump(mode="json") if request.frame is RecordingFrame.WORK else None,
            "divisor": request.divisor, "loop_rate_hz": current.loop_rate_hz,
            "rate_hz": current.loop_rate_hz / request.divisor, "duration_s": request.duration_s,
            "start": request.start.value, "calibration_id": current.calibration_id,
            "started_utc": datetime.fromtimestamp(started_wall, timezone.utc).isoformat() if first_t_ns else None,
            "started_monotonic_s": first_t_ns / 1e9 if first_t_ns is not None else None,
            "first_cycle": current.first_cycle, "rows_requested": current.rows_requested,
            "rows_written": current.received, "cycles_missing": current.cycles_missing,
            "rows_lost": recorder.lost if recorder.recording == current.recording else 0, "faults_during": current.faults_seen,
            "ended": ended.value, "columns": [{"name": name, "unit": unit} for name, unit in columns(request.signals)],
        }
        try:
            self._data.write_new(str(path.with_suffix(".json")), (json.dumps(side, indent=2) + "\n").encode("utf-8"))
        except ApiError as error:  # the CSV stands; say why its side file does not
            side["side_file_error"] = error.message
        self.last = side
        self._finished.notify_all()


def _pose_cells(pose: Sequence[float] | None, frames: Frames | None, active: ActiveGeometry | None,
                in_work: bool) -> list[str]:
    """A pose (relative mm/rad) as six cells, mm and deg, in the work frame with ``in_work``."""
    if pose is None or (in_work and (frames is None or active is None)):
        return [""] * 6
    shown = convert(pose, None, frames, active.home) if in_work and active is not None else pose
    x, y, z, roll, pitch, yaw = shown
    return [f"{x:.6f}", f"{y:.6f}", f"{z:.6f}", f"{math.degrees(roll):.7f}", f"{math.degrees(pitch):.7f}",
            f"{math.degrees(yaw):.7f}"]


def _request_problem(request: RecordingRequest) -> str | None:
    if not NAME_PATTERN.match(request.name) or request.name.endswith(".partial"):
        return (f"name {request.name!r}: a bare file name (letters, digits, '.', '_', '-'; up to 100), without a "
                "directory: the files go to the first data directory")
    if unknown := [s for s in request.signals if s not in SIGNALS]:
        return f"unknown signals {unknown}: choose among {', '.join(SIGNALS)}"
    if not request.signals:
        return f"no signals: choose among {', '.join(SIGNALS)}"
    if isinstance(request.divisor, bool) or not isinstance(request.divisor, int) or request.divisor < 1:
        return f"divisor {request.divisor!r}: a whole number ≥ 1 (1: every cycle)"
    if not (0 < request.duration_s <= MAX_DURATION_S):
        return f"duration_s {request.duration_s!r}: more than 0 and at most {MAX_DURATION_S:g} s"
    return None


def _exists(name: str, directory: int) -> bool:
    try:
        os.stat(name, dir_fd=directory, follow_symlinks=False)
    except FileNotFoundError:
        return False
    return True
