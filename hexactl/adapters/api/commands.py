"""Carrying out API requests on the controller: request model in, reply fields out.

Files named by requests are read and parsed here (in the API thread), so the control
loop only ever receives validated objects.
"""

from __future__ import annotations

import dataclasses
from enum import Enum
from math import isfinite
from typing import Any

import numpy as np

from hexactl.adapters.api.messages import (
    AbortRequest,
    DisableRequest,
    EnableRequest,
    EstopRequest,
    LegLockRequest,
    LegUnlockRequest,
    LoadCalibrationRequest,
    MoveRequest,
    PauseRequest,
    PlayRequest,
    Request,
    ResetRequest,
    ResumeRequest,
    RollbackCalibrationRequest,
    StatusRequest,
    StopRequest,
    ValidatePoseRequest,
)
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.port import ControllerPort, Result
from hexactl.adapters.api.sequences import resolve_sequence
from hexactl.adapters.api.wire import ApiError, ErrorCode, problems_error
from hexactl.adapters.files.geometry_file import geometry_id, parse_geometry
from hexactl.kinematics.geometry import Geometry, GeometryError


class CommandHandler:
    """The :data:`~hexactl.adapters.api.server.Handler` of the service: one method per
    command, each returning the reply's fields or raising :class:`ApiError`."""

    def __init__(self, controller: ControllerPort, data: DataDirectories) -> None:
        self.controller = controller
        self.data = data

    def __call__(self, request: Request) -> dict[str, Any]:
        controller = self.controller
        match request:
            case StatusRequest():
                return {"status": controller.telemetry()}
            case EnableRequest():
                return _checked(controller.enable())
            case DisableRequest():
                return _checked(controller.disable())
            case StopRequest():
                return _checked(controller.stop())
            case EstopRequest():
                return _checked(controller.estop())
            case ResetRequest():
                return _checked(controller.reset())
            case MoveRequest():
                return _checked(controller.move(request.pose, request.duration, request.speed))
            case ValidatePoseRequest():
                return self._validate_pose(request)
            case LegLockRequest():
                return _checked(controller.leg_lock(request.leg))
            case LegUnlockRequest():
                return _checked(controller.leg_unlock())
            case PlayRequest():
                sequence = resolve_sequence(request.sequence, self.data)
                fields = _checked(controller.play(sequence))
                return {**fields, "sequence": {"name": sequence.name, "index": 0, "total": len(sequence.waypoints)}}
            case PauseRequest():
                return _checked(controller.pause())
            case ResumeRequest():
                return _checked(controller.resume())
            case AbortRequest():
                return _checked(controller.abort())
            case LoadCalibrationRequest():
                fields = _checked(controller.load_calibration(self._calibration(request)))
                return {**fields, **_geometry_fields(controller.geometry)}
            case RollbackCalibrationRequest():
                fields = _checked(controller.rollback_calibration())
                return {**fields, **_geometry_fields(controller.geometry)}
        raise AssertionError(f"no handler for {type(request).__name__}")  # the union and this match disagree

    def _validate_pose(self, request: ValidatePoseRequest) -> dict[str, Any]:
        assessment = self.controller.assess(request.pose)
        condition = assessment.jacobian_condition
        return {
            "reachable": assessment.ok,
            "violations": jsonable(assessment.violations),
            "leg_setpoints": list(assessment.sensor_mm),
            "jacobian_condition": condition if isfinite(condition) else None,
        }

    def _calibration(self, request: LoadCalibrationRequest) -> Geometry:
        if request.path is not None:
            path, text = self.data.read_text(request.path, ErrorCode.INVALID_CALIBRATION)
            source = str(path)
        else:
            text, source = request.toml or "", "toml"
        try:
            return parse_geometry(text, source)
        except GeometryError as error:
            raise problems_error(ErrorCode.INVALID_CALIBRATION, str(error)) from None


def _checked(result: Result) -> dict[str, Any]:
    """The reply fields of a successful result; :class:`ApiError` with the controller's
    code for a refusal."""
    if not result.ok:
        raise ApiError(result.code or ErrorCode.INTERNAL_ERROR, result.message, jsonable(result.details))
    return {"message": result.message} if result.message else {}


def _geometry_fields(geometry: Geometry) -> dict[str, Any]:
    return {"calibration_id": geometry_id(geometry), "name": geometry.name}


def jsonable(value: Any) -> Any:
    """``value`` with dataclasses, tuples, enums and numpy scalars turned into JSON types, and
    non-finite floats into null (JSON has no NaN)."""
    if isinstance(value, Enum):
        return value.value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {field.name: jsonable(getattr(value, field.name)) for field in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.generic):  # numpy scalars from the kinematics
        value = value.item()
    if isinstance(value, float) and not isfinite(value):
        return None
    return value
