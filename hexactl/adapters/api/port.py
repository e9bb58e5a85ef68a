"""What the API needs of the controller: the part of
:class:`hexactl.control.controller.Controller` it drives, as a Protocol (so tests can
put a fake behind the real server).

Poses are relative to the zero posture, mm and deg, unless a ``frame`` says otherwise;
times in s. No method raises for
bad input: each returns a :class:`~hexactl.control.results.CommandResult` whose
``error`` the API sends as its error code.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.planning import ActiveGeometry
from hexactl.control.telemetry import EventLog, Telemetry
from hexactl.control.sequence_player import SequenceReport
from hexactl.control.results import CommandResult
from hexactl.control.sequences import MotionSequence
from hexactl.control.stream_commands import TargetResult
from hexactl.control.validated_under import ValidatedUnder
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.geometry import Geometry


class ControllerPort(Protocol):
    """The controller as the API thread calls it."""

    def enable(self, *, deadline_ns: int | None = None) -> CommandResult: ...

    def disable(self) -> CommandResult: ...

    def stop(self) -> CommandResult: ...

    def estop(self) -> CommandResult: ...

    def reset(self) -> CommandResult: ...

    def move(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
             frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
             validated_under: ValidatedUnder | None = None, *, deadline_ns: int | None = None) -> CommandResult:
        """Success details: ``goal`` (as planned, relative to the zero posture),
        ``duration_s``; refused ``changed_since_validation`` when the frames or the
        calibration differ from ``validated_under``. ``deadline_ns``, here and below:
        monotonic time after which the loop refuses the command as ``expired``."""
        ...

    def validate_pose(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
                      frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
                      validated_under: ValidatedUnder | None = None) -> CommandResult:
        """What :meth:`move` would answer, without moving; success details also
        ``predicted_accuracy`` and ``validated_under`` (what it validated under)."""
        ...

    def predicted_accuracy(self) -> dict[str, Any] | None:
        """The predicted 1σ error at the tool point for the commanded pose now."""
        ...

    def set_frames(self, frames: OperatorFrames) -> CommandResult:
        """Success details: ``frames``."""
        ...

    def operator_frames(self) -> OperatorFrames: ...

    def jog(self, velocity: Sequence[float], frame: Frame = Frame.ZERO, *, renews: int | None = None,
            deadline_ns: int | None = None) -> CommandResult:
        """Success details: ``jog`` (its number), ``goal`` (where its plan ends, relative to the
        zero posture; absent on a renewal), ``speed``, ``end``, ``to_limit``, ``deadman_s``."""
        ...

    def wave(self, spec: WaveSpec, *, deadline_ns: int | None = None) -> CommandResult:
        """Success details: :meth:`~hexactl.control.wave_planning.WavePlan.summary`'s
        (``duration_s``, the peak leg speed and acceleration, the peak pose velocity)."""
        ...

    def validate_wave(self, spec: WaveSpec) -> CommandResult:
        """What :meth:`wave` would answer, without moving."""
        ...

    def stream_open(self, source: str, frame: Frame | str = Frame.ZERO, timeout_s: float = 0.1, *,
                    deadline_ns: int | None = None) -> CommandResult:
        """Success details: ``stream`` (its number), ``velocity_scale`` (the fraction of the
        stream's velocity limits available in every direction at once where it starts)."""
        ...

    def stream_close(self) -> CommandResult: ...

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None = None) -> TargetResult: ...

    def leg_lock(self, leg: int, *, deadline_ns: int | None = None) -> CommandResult: ...

    def leg_unlock(self, *, deadline_ns: int | None = None) -> CommandResult: ...

    def play(self, sequence: MotionSequence, *, deadline_ns: int | None = None) -> CommandResult:
        """Success details: ``duration_s`` (with dwells), ``waypoints``, ``goal``; in leg-lock
        mode ``lock_corrections_mm``."""
        ...

    def validate_sequence(self, sequence: MotionSequence) -> CommandResult:
        """Would :meth:`play` take its paths now? The same details on success."""
        ...

    def pause(self) -> CommandResult: ...

    def resume(self, *, deadline_ns: int | None = None) -> CommandResult: ...

    def abort(self) -> CommandResult: ...

    def load_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Success details: ``calibration_id``, ``change_mm``."""
        ...

    def rollback_calibration(self) -> CommandResult:
        """Success details: ``calibration_id``, ``change_mm``."""
        ...

    def validate_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Would load_calibration accept it? Success details: ``calibration_id``, ``change_mm``."""
        ...

    def active_geometry(self) -> ActiveGeometry: ...

    def sequence_records(self) -> SequenceReport | None:
        """The playing or last played sequence's dwell records."""
        ...

    def telemetry(self) -> Telemetry: ...

    def events(self, after: int = 0) -> EventLog:
        """The loop's kept events numbered after ``after``, oldest first."""
        ...


class RecorderPort(Protocol):
    """The data recorder's writer (:class:`hexactl.application.recording.Recordings`):
    each method answers a reply's fields or raises
    :class:`~hexactl.adapters.api.wire.ApiError`."""

    def start(self, name: str, signals: Sequence[str], frame: str, divisor: int, duration_s: float,
              start: str) -> dict[str, Any]: ...

    def stop(self) -> dict[str, Any]: ...

    def state(self) -> dict[str, Any]: ...

    def reserved(self) -> Mapping[Path, str]: ...


class StreamInput(Protocol):
    """Where the service takes a pose stream's samples
    (:class:`~hexactl.adapters.api.stream_receiver.StreamReceiver`)."""

    @property
    def endpoints(self) -> dict[str, str | None]:
        """``zmq``: the endpoint to connect a PUSH socket to; ``udp``: HOST:PORT, or None."""
        ...

    @property
    def running(self) -> bool:
        """Whether it takes samples."""
        ...

    def view(self) -> dict[str, Any]:
        """What it counted and measured, for telemetry's ``stream_input``."""
        ...
