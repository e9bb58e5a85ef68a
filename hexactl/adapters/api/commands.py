"""Carrying out API requests on the controller: request model in, reply fields out.

Files named by requests are read and parsed here, in the API thread, so the control
loop only ever receives validated objects.
"""

from __future__ import annotations

import base64
import csv
import io
import logging
import os
import secrets
import time
from collections.abc import Callable, Sequence
from pathlib import Path, PurePath
from typing import Any

from pydantic import ValidationError

from hexactl.adapters.api.messages import (
    MAX_FILES_LISTED,
    AbortRequest,
    ClearFramesRequest,
    DisableRequest,
    EnableRequest,
    EstopRequest,
    EventsRequest,
    FramesRequest,
    JogRequest,
    LegLockRequest,
    LegUnlockRequest,
    LoadCalibrationRequest,
    MeasureRequest,
    MoveRequest,
    PauseRequest,
    PlayRequest,
    RecordRequest,
    RecordStatusRequest,
    RecordStopRequest,
    Request,
    ResetRequest,
    ResumeRequest,
    RollbackCalibrationRequest,
    SaveRecordingRequest,
    ValidateCalibrationRequest,
    GeometryRequest,
    FilesRequest,
    ProgressRequest,
    ReadFileRequest,
    SetFramesRequest,
    StatusRequest,
    StopRequest,
    StreamCloseRequest,
    StreamOpenRequest,
    ValidatePoseRequest,
    ValidateSequenceRequest,
    ValidateWaveRequest,
    WaveFigures,
    WaveRequest,
)
from hexactl.adapters.api.campaign_board import CampaignBoard
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.port import ControllerPort, RecorderPort, StreamInput
from hexactl.adapters.api.sequences import resolve_sequence
from hexactl.adapters.api.wire import ApiError, ErrorCode, error_body, jsonable, problems_error, validation_problems
from hexactl.adapters.files.atomic import write_problem
from hexactl.adapters.files.frames_file import file_differs, save_frames
from hexactl.adapters.files.geometry_file import geometry_id, parse_geometry
from hexactl.adapters.files.kept_calibration import CalibrationKeeper
from hexactl.adapters.files.sequence_file import dwell_header, dwell_rows
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.results import CommandResult
from hexactl.control.results import ErrorCode as RefusalCode
from hexactl.control.sequence_player import SequenceReport
from hexactl.control.submitter import commands_from
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.geometry import Geometry, GeometryError
from hexactl.kinematics.validation_messages import describe_validation_error

log = logging.getLogger(__name__)

JOG_REPLY = ("jog", "goal", "speed", "end", "to_limit", "deadman_s")
"""The fields of a ``jog`` reply besides ``message``."""

GEOMETRY_REPLY_EXCLUDES = {"calibration": {"parameter_covariance"}}
"""Left out of ``geometry``'s reply: the covariance (48×48 numbers) is the calibration
file's, not a drawing's."""

TOML_SOURCE = "request"
"""The calibration source recorded for a calibration sent as text."""

Instrument = Callable[[], Sequence[Sequence[float]]]
"""A measuring instrument: measures the platform's feature points now and returns them
(K × [x, y, z], fixed frame, mm, in the geometry's order); raises
:class:`MeasurementError` when it cannot."""


class MeasurementError(Exception):
    """The instrument could not measure; the message says why."""


class CommandHandler:
    """The :data:`~hexactl.adapters.api.server.Handler` of the service: returns each
    request's reply fields or raises :class:`ApiError` (with the controller's code for
    its refusals). ``instrument`` answers ``measure`` (None: ``no_instrument``).

    ``deadline_ns`` (monotonic; None: none) goes with every command that sets the platform
    moving or changes how it moves, so that the loop refuses it (``expired``) once its
    sender has stopped waiting. ``load_calibration`` and ``rollback_calibration`` are
    checked against it when taken from the queue only. ``frames_file``: where the
    operator's frames are saved whenever they change (None: not saved). ``recorder``:
    the data recorder's writer (None: ``record`` is refused ``no_recorder``).
    ``stream_input``: where a pose stream's samples are taken (None: ``stream_open`` is
    refused ``no_stream_input``). ``keeper``: keeps the calibration in force for a restart,
    following the loop's snapshot with each telemetry :meth:`record` and after each load
    and rollback, whose reply says where it is kept (None: not kept)."""

    def __init__(self, controller: ControllerPort, data: DataDirectories, instrument: Instrument | None = None,
                 frames_file: Path | None = None, recorder: RecorderPort | None = None,
                 stream_input: StreamInput | None = None, *, keeper: CalibrationKeeper | None = None) -> None:
        self.keeper = keeper
        self.stream_input = stream_input
        self.controller = controller
        self.data = data
        self.instrument = instrument
        self.frames_file = frames_file
        self.recorder = recorder
        self.campaign = CampaignBoard()
        self.run = secrets.token_hex(4)  # this service's run: its events are numbered from 1 in each
        self._saved: tuple[str, tuple[float, ...]] | None = None  # the dwell records save_recording wrote last
        self._outside = False  # the last telemetry had the platform outside the soft limits

    def record(self) -> dict[str, Any]:
        """A telemetry record: the controller's, with what a client's campaign said last and
        this service's :attr:`run` (a client reaching it on two endpoints can tell they are
        one service). The calibration in force is kept first if it changed (the publisher
        calls this every period: a swap is kept however it came about, even after
        ``loop_timeout``)."""
        if self.keeper is not None:
            self.keeper.follow()
        stream_input = self.stream_input.view() if self.stream_input is not None else None
        telemetry = self.controller.telemetry()
        if telemetry.outside_soft_limits and not self._outside:  # said once, as it happens (a start there too)
            log.warning("the platform is outside the operator's soft limits: %s; moves may only go back inside",
                        "; ".join(telemetry.outside_soft_limits))
        self._outside = bool(telemetry.outside_soft_limits)
        record = {**jsonable(telemetry), "campaign": self.campaign.view(), "stream_input": stream_input, "run": self.run}
        if (recording := record.get("recording")) and recording["state"] == "done" and self.recorder is not None:
            written = self.recorder.state()
            if written["state"] == "done" and written.get("name") == recording["name"]:
                recording["file"] = {"ended": written["ended"], "faults_during": written["faults_during"]}
        return record

    def __call__(self, request: Request, deadline_ns: int | None = None, sender: str | None = None) -> dict[str, Any]:
        """Carry out ``request``; the commands it hands the loop name ``sender`` (who sent it, for people)."""
        with commands_from(sender):
            return self._carry_out(request, deadline_ns)

    def _carry_out(self, request: Request, deadline_ns: int | None) -> dict[str, Any]:
        controller = self.controller
        match request:
            case StatusRequest():
                active = controller.active_geometry()
                return {"status": self.record(), "calibration_source": active.source,
                        "calibration_warnings": active.geometry.identification_warnings,
                        "predicted_accuracy": controller.predicted_accuracy()}
            case EnableRequest():
                return _checked(controller.enable(deadline_ns=deadline_ns))
            case DisableRequest():
                return _checked(controller.disable())
            case StopRequest():
                return _checked(controller.stop())
            case EstopRequest():
                return _checked(controller.estop())
            case ResetRequest():
                return _checked(controller.reset())
            case MoveRequest():
                result = controller.move(request.pose, request.duration, request.speed, Frame(request.frame),
                                         request.relative, request.tolerance_mm, request.validated_under,
                                         deadline_ns=deadline_ns)
                return _checked(result, goal=result.details.get("goal"), tool_goal=result.details.get("tool_goal"),
                                duration=result.details.get("duration_s"))
            case ValidatePoseRequest():
                return self._validate_pose(request)
            case JogRequest():
                result = self.controller.jog(request.velocity, Frame(request.frame), renews=request.renews,
                                             restarts=request.restarts,
                                             deadline_ns=deadline_ns)
                return _checked(result, **{key: result.details.get(key) for key in JOG_REPLY})
            case WaveRequest():
                result = controller.wave(_wave_spec(request), deadline_ns=deadline_ns)
                return _checked(result, **_wave_figures(result))
            case ValidateWaveRequest():
                return self._validate_wave(request)
            case StreamOpenRequest():
                return self._stream_open(request, deadline_ns)
            case StreamCloseRequest():
                return _checked(controller.stream_close())
            case LegLockRequest():
                return _checked(controller.leg_lock(request.leg, deadline_ns=deadline_ns))
            case LegUnlockRequest():
                return _checked(controller.leg_unlock(deadline_ns=deadline_ns))
            case ValidateSequenceRequest():  # before its base class: a match takes the first case that fits
                return self._validate_sequence(request)
            case PlayRequest():
                sequence = resolve_sequence(request.sequence, self.data)
                previous = controller.sequence_records()
                result = controller.play(sequence, deadline_ns=deadline_ns)
                reply = _checked(result, name=sequence.name, waypoints=len(sequence.waypoints),
                                 duration=result.details.get("duration_s"),
                                 lock_corrections_mm=result.details.get("lock_corrections_mm"))
                if previous is not None and (unsaved := _unsaved_dwells(previous, self._saved)):
                    reply["message"] += f"; {unsaved}"
                return reply
            case PauseRequest():
                return _checked(controller.pause())
            case ResumeRequest():
                return _checked(controller.resume(deadline_ns=deadline_ns))
            case AbortRequest():
                return _checked(controller.abort())
            case ValidateCalibrationRequest():  # before its base class: a match takes the first case that fits
                return self._validate_calibration(request)
            case LoadCalibrationRequest():
                geometry, calibration_id, source = self._calibration(request)
                return self._kept(_calibration_fields(controller.load_calibration(geometry, calibration_id, source)))
            case EventsRequest():  # the loop's clock is this host's monotonic one
                return {**jsonable(controller.events(request.after, time.monotonic_ns())), "run": self.run}
            case GeometryRequest():
                active = controller.active_geometry()
                return {"calibration_id": active.calibration_id, "source": active.source,
                        "geometry": active.geometry.model_dump(mode="json", exclude=GEOMETRY_REPLY_EXCLUDES)}
            case FilesRequest():
                return {"files": self.data.files(MAX_FILES_LISTED)}
            case ProgressRequest():
                self.campaign.update(request)
                return {"message": "noted"}
            case ReadFileRequest():
                path, data, size = self.data.read_chunk(request.path, request.offset, request.length)
                return {"path": str(path), "offset": request.offset, "data_b64": base64.b64encode(data).decode("ascii"),
                        "size": size, "eof": request.offset + len(data) >= size}
            case RollbackCalibrationRequest():
                return self._kept(_calibration_fields(controller.rollback_calibration()))
            case SaveRecordingRequest():
                return self._save_recording(request)
            case MeasureRequest():
                return self._measure()
            case SetFramesRequest():
                return self._set_frames(request)
            case ClearFramesRequest():
                return self._replace_frames(OperatorFrames(), "frames cleared: poses relative to the zero posture")
            case FramesRequest():
                return self._frames()
            case RecordRequest():
                return self._recorder().start(request.name, request.signals, request.frame, request.divisor,
                                              request.duration_s, request.start)
            case RecordStopRequest():
                return self._recorder().stop()
            case RecordStatusRequest():
                return self._recorder().state()
        raise AssertionError(f"no handler for {type(request).__name__}")  # the union and this match disagree

    def _stream_open(self, request: StreamOpenRequest, deadline_ns: int | None) -> dict[str, Any]:
        if self.stream_input is None:
            raise ApiError(ErrorCode.NO_STREAM_INPUT, "this service takes no stream input (a test's handler): stream "
                           "with hexactl serve")
        if not self.stream_input.running:
            raise ApiError(ErrorCode.NO_STREAM_INPUT, "the stream input has stopped (the service's log says why): "
                           "restart the service to stream")
        result = self.controller.stream_open(request.source, Frame(request.frame), request.timeout_ms / 1000.0,
                                             deadline_ns=deadline_ns)
        return _checked(result, stream=result.details.get("stream"), velocity_scale=result.details.get("velocity_scale"),
                        endpoints=self.stream_input.endpoints)

    def _recorder(self) -> RecorderPort:
        if self.recorder is None:
            raise ApiError(ErrorCode.NO_RECORDER, "this service has no data recorder (a test's handler): record with "
                           "hexactl serve")
        return self.recorder

    def _validate_pose(self, request: ValidatePoseRequest) -> dict[str, Any]:
        result = self.controller.validate_pose(request.pose, request.duration, request.speed, Frame(request.frame),
                                               request.relative, request.tolerance_mm, request.validated_under)
        if result.ok:
            return {"valid": True, "goal": result.details.get("goal"), "tool_goal": result.details.get("tool_goal"),
                    "duration": result.details.get("duration_s"),
                    "predicted_accuracy": result.details.get("predicted_accuracy"), "refusal": None,
                    "validated_under": jsonable(result.details.get("validated_under"))}
        return {"valid": False, "goal": None, "tool_goal": None, "duration": None, "predicted_accuracy": None,
                "refusal": error_body(_code(result), result.message, _details(result)), "validated_under": None}

    def _validate_wave(self, request: ValidateWaveRequest) -> dict[str, Any]:
        result = self.controller.validate_wave(_wave_spec(request))
        if result.ok:
            return {"message": result.message, "valid": True, "refusal": None,
                    "wave": jsonable(_wave_figures(result))}
        return {"valid": False, "wave": None, "refusal": error_body(_code(result), result.message, _details(result))}

    def _validate_sequence(self, request: ValidateSequenceRequest) -> dict[str, Any]:
        sequence = resolve_sequence(request.sequence, self.data)  # a bad file is refused as play refuses it
        result = self.controller.validate_sequence(sequence)
        named = {"name": sequence.name, "waypoints": len(sequence.waypoints)}
        if result.ok:
            return {"valid": True, **named, "duration": result.details.get("duration_s"),
                    "goal": result.details.get("goal"),
                    "lock_corrections_mm": result.details.get("lock_corrections_mm"), "refusal": None}
        return {"valid": False, **named, "duration": None, "goal": None, "lock_corrections_mm": None,
                "refusal": error_body(_code(result), result.message, _details(result))}

    def _set_frames(self, request: SetFramesRequest) -> dict[str, Any]:
        current = self.controller.operator_frames()
        given = {name: getattr(request, name) for name in ("work", "tool", "soft_limits") if getattr(request, name) is not None}
        try:
            if request.soft_limit_changes is not None:
                given["soft_limits"] = request.soft_limit_changes.applied_to(current.soft_limits)
            frames = OperatorFrames.model_validate({**dict(current), **given})
        except ValidationError as error:
            raise ApiError(ErrorCode.INVALID_REQUEST, describe_validation_error(error, "set_frames", model=OperatorFrames),
                           validation_problems(error, OperatorFrames)) from None
        return self._replace_frames(frames)

    def _replace_frames(self, frames: OperatorFrames, message: str | None = None) -> dict[str, Any]:
        """Save ``frames`` and make them the controller's: written to disk first, taken by
        the controller, then in the file's place; written or taken not, nothing changes
        (what is in force is what a restart restores). Found from outside: taken first, then
        written to a full disk, new soft limits were in force until they were put back."""
        before = self.controller.operator_frames()
        taken: list[CommandResult] = []

        def take() -> None:
            taken.append(result := self.controller.set_frames(frames))
            if not result.ok:
                raise ApiError(_code(result), result.message, _details(result))

        if self.frames_file is None:
            take()
            return {"message": message or taken[0].message, "frames": jsonable(frames)}
        try:
            aside = save_frames(frames, self.frames_file, before, before_rename=take)
        except OSError as error:
            where = "they are not in force: the ones before are, and stay in the file"
            if taken and taken[0].ok:  # the rename failed after the controller took them
                undone = self.controller.set_frames(before)
                if not undone.ok:
                    where = (f"they are in force all the same: putting the ones before back was refused "
                             f"({undone.message}), and a restart would restore the file's")
            raise ApiError(ErrorCode.WRITE_FAILED, f"{self.frames_file}: the frames could not be saved: "
                           f"{write_problem(error)}; {where}; set them again once it can be written") from None
        said = message or taken[0].message
        if aside is not None:
            said += (f"; {self.frames_file} had been changed since the service read it (at start only): that "
                     f"version, never in force, is kept as {aside}")
            log.warning("%s", said)
        return {"message": said, "frames": jsonable(frames)}

    def _frames(self) -> dict[str, Any]:
        """The frames in force; the message says if the file they are kept in no longer holds
        them (a hand edit is not read until a restart: the operator must know which is in force)."""
        frames = self.controller.operator_frames()
        reply: dict[str, Any] = {"frames": jsonable(frames)}
        if self.frames_file is not None and (problem := file_differs(self.frames_file, frames)):
            remedy = ("a restart would start with no frames and no soft limits: set them again (hexactl frames) to "
                      "keep them, or clear them (hexactl frames --clear) if that is what was meant"
                      if not os.path.lexists(self.frames_file) else
                      "set the frames you want (the changed file is then kept aside) or restart the service to use "
                      "the file's")
            reply["message"] = (f"in force; but {self.frames_file}, where they are kept, no longer holds them: "
                                f"{problem}. The service reads that file at start only: {remedy}")
        return reply

    def _kept(self, fields: dict[str, Any]) -> dict[str, Any]:
        """A calibration change's reply ``fields``, once the calibration now in force is kept
        for a restart; its message says so, or why it is not. (A change refused, or answered
        ``loop_timeout``, raised before this: what the loop does with it is kept by
        :meth:`record`.)"""
        if self.keeper is None:
            return fields
        return {**fields, "message": f"{fields['message']}; {self.keeper.keep_now()}"}

    def _calibration(self, request: LoadCalibrationRequest) -> tuple[Geometry, str, str]:
        """The geometry a load or validate request names, parsed and validated, its
        calibration id (:func:`geometry_id`, the one rule for both) and its source. With
        ``expected_id`` (the id a preview answered), :class:`ApiError`
        ``changed_since_validation`` if what is read now is another calibration."""
        if request.path is not None:
            path, text = self.data.read_text(request.path, ErrorCode.INVALID_CALIBRATION)
            source = str(path)
        else:
            text = request.toml or ""
            source = f"{TOML_SOURCE} ({request.source})" if request.source else TOML_SOURCE
        try:
            geometry = parse_geometry(text, source)
        except GeometryError as error:
            raise problems_error(ErrorCode.INVALID_CALIBRATION, str(error)) from None
        calibration_id = geometry_id(geometry)
        if request.expected_id is not None and calibration_id != request.expected_id:
            what = f"{request.path} now holds" if request.path is not None else "the text sent is"
            raise ApiError(RefusalCode.CHANGED_SINCE_VALIDATION,
                           f"{what} calibration {calibration_id}, not calibration {request.expected_id} as previewed "
                           f"(expected_id): it changed since the preview, and nothing was loaded; preview it again "
                           f"to see the change it would make, then apply that",
                           {"expected_id": request.expected_id, "calibration_id": calibration_id})
        return geometry, calibration_id, source

    def _validate_calibration(self, request: ValidateCalibrationRequest) -> dict[str, Any]:
        try:
            geometry, calibration_id, source = self._calibration(request)
        except ApiError as error:
            return {"message": error.message, "valid": False, "calibration_id": None, "change_mm": None,
                    "refusal": error_body(error.code, error.message, error.details)}
        result = self.controller.validate_calibration(geometry, calibration_id, source)
        if not result.ok:
            return {"message": result.message, "valid": False, "calibration_id": None, "change_mm": None,
                    "refusal": error_body(_code(result), result.message, _details(result))}
        return {"message": result.message, "valid": True, "calibration_id": result.details["calibration_id"],
                "change_mm": result.details["change_mm"], "refusal": None, "warnings": result.details.get("warnings", [])}

    def _save_recording(self, request: SaveRecordingRequest) -> dict[str, Any]:
        report = self.controller.sequence_records()
        if report is None:
            raise ApiError(ErrorCode.NO_RECORDING, "no sequence has been played yet")
        table = io.StringIO()
        writer = csv.writer(table, lineterminator="\n")
        writer.writerow(dwell_header())
        writer.writerows(dwell_rows(report.records))
        reserved = self.recorder.reserved() if self.recorder is not None else None
        target = self.data.write_new(_csv_name(request.path), table.getvalue().encode("utf-8"), reserved)
        self._saved = _dwells(report)
        return {"path": str(target), "name": report.name, "status": report.status, "records": len(report.records)}

    def _measure(self) -> dict[str, Any]:
        if self.instrument is None:
            raise ApiError(ErrorCode.NO_INSTRUMENT, "this service has no measuring instrument (only the simulator has one): "
                           "measure the platform with yours")
        try:
            points = self.instrument()
        except MeasurementError as error:
            raise ApiError(ErrorCode.MEASUREMENT_FAILED, str(error)) from None
        return {"points": [[float(value) for value in point] for point in points]}


def _dwells(report: SequenceReport) -> tuple[str, tuple[float, ...]]:
    """A sequence's dwell records told apart from any other's by their times (equal values
    would not do: a record without feedback holds NaN, which equals nothing)."""
    return report.name, tuple(record.t_s for record in report.records)


def _unsaved_dwells(report: SequenceReport, saved: tuple[str, tuple[float, ...]] | None) -> str | None:
    """What a play that replaces ``report``'s dwell records loses: those after the ones
    ``saved`` (:func:`_dwells` of the last save; one made while it played holds its first
    records only), or None when none."""
    name, times = _dwells(report)
    kept = saved[1] if saved is not None and saved[0] == name and times[:len(saved[1])] == saved[1] else ()
    if len(times) == len(kept):
        return None
    after = f" after the {len(kept)} saved" if kept else ""
    return (f"the {len(times) - len(kept)} dwell record(s) of {name}{after}, never saved, are replaced by this "
            "sequence's (save_recording saves a sequence's records before the next one plays)")


def _csv_name(path: str) -> str:
    """``path``, a CSV file's: another ending, or none, is :class:`ApiError`
    ``invalid_request`` (a CSV named ``run1`` or ``run1.json`` misleads every reader of the
    folder, and a plotter or spreadsheet does not open it)."""
    if PurePath(path).suffix.lower() != ".csv":
        raise ApiError(ErrorCode.INVALID_REQUEST, f"{path}: a recording is CSV: name it with the ending .csv")
    return path


def _code(result: CommandResult) -> str:
    return result.error.value if result.error is not None else ErrorCode.INTERNAL_ERROR.value


def _details(result: CommandResult) -> dict[str, Any]:
    """A refusal's details for a client: without the loop's ``ticket``, which numbers
    commands inside the service and means nothing to a client."""
    return jsonable({key: value for key, value in result.details.items() if key != "ticket"})


def _wave_spec(request: WaveRequest | ValidateWaveRequest) -> WaveSpec:
    """The wave a request asks for (validated with it: the request is one)."""
    return WaveSpec.model_validate({name: getattr(request, name) for name in WaveSpec.model_fields})


def _wave_figures(result: CommandResult) -> dict[str, Any]:
    """A wave's :class:`WaveFigures` from its result's details (``duration_s``: ``duration``, as moves')."""
    details = {**result.details, "duration": result.details.get("duration_s")}
    return {key: details.get(key) for key in WaveFigures.model_fields}


def _checked(result: CommandResult, **fields: Any) -> dict[str, Any]:
    """``message`` and ``fields`` for a successful result; :class:`ApiError` with the
    controller's code and details for a refusal."""
    if not result.ok:
        raise ApiError(_code(result), result.message, _details(result))
    return {"message": result.message, **jsonable(fields)}


def _calibration_fields(result: CommandResult) -> dict[str, Any]:
    return _checked(result, calibration_id=result.details.get("calibration_id"), change_mm=result.details.get("change_mm"),
                    warnings=result.details.get("warnings", []))
