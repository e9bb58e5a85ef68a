"""The API's messages as pydantic models: the user-facing contract (docs/api.md).

Every pose is ``[x, y, z, roll, pitch, yaw]`` in mm and degrees relative to the zero
posture; leg values are actuator sensor readings in mm; times in s unless the name
says otherwise (``_us``: microseconds).

Requests are validated strictly (no coercion: ``"1"`` is not a number, ``true`` is not
an integer), extra keys are refused and floats must be finite. Replies and telemetry
are built by the service; their models exist so the schema documents them and tests
can check what is sent.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union, get_args

from pydantic import BaseModel, ConfigDict, Field, JsonValue, model_validator

PROTOCOL_VERSION = 1

Pose = Annotated[
    list[float],
    Field(min_length=6, max_length=6, description="[x, y, z, roll, pitch, yaw], mm and deg, relative to the zero posture"),
]
LegValues = Annotated[list[float], Field(min_length=6, max_length=6, description="legs 1–6, sensor mm")]
Leg = Annotated[int, Field(ge=1, le=6, description="leg number 1–6")]
ErrorCodeText = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$", description="snake_case error code")]
RequestId = Annotated[JsonValue, Field(description="any JSON value; echoed in the reply")]


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


# -- requests ------------------------------------------------------------------------


class _Request(_Message):
    v: Literal[1] = Field(description="protocol version")
    id: RequestId


class StatusRequest(_Request):
    """Reply with the current telemetry record."""

    cmd: Literal["status"]


class EnableRequest(_Request):
    """Energise the actuators; the platform holds its pose."""

    cmd: Literal["enable"]


class DisableRequest(_Request):
    """De-energise the actuators (brakes hold)."""

    cmd: Literal["disable"]


class StopRequest(_Request):
    """Halt any motion smoothly (jerk-limited) and stay enabled."""

    cmd: Literal["stop"]


class EstopRequest(_Request):
    """Emergency stop: every actuator stops and holds at once; needs ``reset``."""

    cmd: Literal["estop"]


class ResetRequest(_Request):
    """Clear faults and an emergency stop whose cause is gone; ends disabled."""

    cmd: Literal["reset"]


class MoveRequest(_Request):
    """Move to ``pose``; refused whole (``out_of_workspace``) if any point of the path violates a limit."""

    cmd: Literal["move"]
    pose: Pose
    duration: Duration | None = Field(default=None, description="minimum duration, s; default: as fast as the limits allow")
    speed: Speed | None = Field(default=None, description="fraction of the velocity limits; default 1")


class ValidatePoseRequest(_Request):
    """Check ``pose`` against every limit without moving."""

    cmd: Literal["validate_pose"]
    pose: Pose


class LegLockRequest(_Request):
    """Lock one leg at its current length (leg-lock calibration mode)."""

    cmd: Literal["leg_lock"]
    leg: Leg


class LegUnlockRequest(_Request):
    """Release the locked leg."""

    cmd: Literal["leg_unlock"]


Speed = Annotated[float, Field(gt=0, le=1, description="fraction of the velocity limits, (0, 1]")]
Duration = Annotated[float, Field(gt=0, description="minimum duration of the move, s")]


class Waypoint(_Message):
    """One waypoint of an inline sequence: the ``[[waypoint]]`` table of a sequence file."""

    pose: Pose
    duration: Duration | None = Field(default=None, description="minimum duration of the move, s; not with speed")
    speed: Speed | None = Field(default=None, description="fraction of the velocity limits; not with duration")
    dwell: float = Field(default=0.0, ge=0, description="time to stay on arrival, s")


class InlineSequence(_Message):
    """A sequence given in the request, as a sequence file would give it."""

    name: str = Field(min_length=1, max_length=200)
    description: str = ""
    waypoints: list[Waypoint] = Field(min_length=1, max_length=1000)


class PlayRequest(_Request):
    """Play a sequence: a built-in name, a file path under a data directory, or inline waypoints."""

    cmd: Literal["play"]
    sequence: str | InlineSequence = Field(description="built-in name, file path, or inline waypoints")


class PauseRequest(_Request):
    """Pause the playing sequence (halts smoothly where it is)."""

    cmd: Literal["pause"]


class ResumeRequest(_Request):
    """Resume the paused sequence."""

    cmd: Literal["resume"]


class AbortRequest(_Request):
    """Abandon the sequence (halts smoothly)."""

    cmd: Literal["abort"]


class LoadCalibrationRequest(_Request):
    """Switch to a calibration: exactly one of ``path`` (under a data directory) or ``toml`` (the file's text)."""

    cmd: Literal["load_calibration"]
    path: str | None = Field(default=None, max_length=4096)
    toml: str | None = None

    @model_validator(mode="after")
    def _exactly_one_source(self) -> LoadCalibrationRequest:
        if (self.path is None) == (self.toml is None):
            raise ValueError("give exactly one of path or toml")
        return self


class RollbackCalibrationRequest(_Request):
    """Return to the calibration active before the last ``load_calibration``."""

    cmd: Literal["rollback_calibration"]


REQUEST_MODELS: tuple[type[_Request], ...] = (
    StatusRequest,
    EnableRequest,
    DisableRequest,
    StopRequest,
    EstopRequest,
    ResetRequest,
    MoveRequest,
    ValidatePoseRequest,
    LegLockRequest,
    LegUnlockRequest,
    PlayRequest,
    PauseRequest,
    ResumeRequest,
    AbortRequest,
    LoadCalibrationRequest,
    RollbackCalibrationRequest,
)

Request = Annotated[Union[REQUEST_MODELS], Field(discriminator="cmd")]  # type: ignore[valid-type]

COMMANDS: tuple[str, ...] = tuple(get_args(model.model_fields["cmd"].annotation)[0] for model in REQUEST_MODELS)
"""Every command name, in the order above."""


# -- telemetry -----------------------------------------------------------------------


class Percentiles(_Message):
    """A timing distribution, µs: percentiles over the recent window, max over the run."""

    p50: float
    p99: float
    p999: float
    max: float


class LoopTelemetry(_Message):
    """The control loop's timing."""

    rate_hz: float = Field(description="loop rate, Hz")
    cycles: int = Field(description="cycles run since start")
    missed: int = Field(description="cycles that woke more than half a period late")
    lateness_us: Percentiles = Field(description="wake-up lateness, µs")
    compute_us: Percentiles = Field(description="time from wake-up to the end of the cycle's work, µs")


class SequenceProgress(_Message):
    """The sequence being played."""

    name: str
    index: int = Field(ge=0, description="waypoint being approached or dwelt at, 0-based")
    total: int = Field(ge=0, description="number of waypoints")


class Fault(_Message):
    """An active fault."""

    code: ErrorCodeText
    message: str
    leg: Leg | None = None


class Telemetry(_Message):
    """One telemetry record: the platform's state as of ``t``."""

    t: float = Field(description="time of the record, s since the Unix epoch")
    state: str = Field(description="controller state, e.g. disabled, enabled, moving, estop")
    pose_command: Pose | None = Field(description="commanded pose; null before the first command")
    pose_measured: Pose | None = Field(description="pose from the actuators' feedback (forward kinematics); null if unknown")
    leg_setpoints: LegValues | None = Field(description="last set-points sent, sensor mm; null before the first")
    leg_feedback: LegValues | None = Field(description="actuator positions reported, sensor mm; null before the first report")
    locked_leg: Leg | None = Field(description="the locked leg, or null")
    calibration_id: str = Field(description="content hash of the active geometry/calibration")
    sequence: SequenceProgress | None = Field(description="the sequence being played, or null")
    faults: list[Fault]
    loop: LoopTelemetry


# -- replies -------------------------------------------------------------------------


class ErrorBody(_Message):
    code: ErrorCodeText
    message: str = Field(description="for people")
    details: JsonValue = Field(default=None, description="for programs, e.g. the violations of out_of_workspace")


class ErrorReply(_Message):
    """A refused or failed request. ``id`` is null when it could not be read from the request."""

    v: Literal[1]
    id: RequestId
    ok: Literal[False]
    error: ErrorBody


class OkReply(_Message):
    """A request that was carried out. ``message`` may say what happened, for people."""

    v: Literal[1]
    id: RequestId
    ok: Literal[True]
    message: str = ""


class StatusReply(OkReply):
    status: Telemetry


class Violation(_Message):
    """A limit a pose violates: ``value`` against ``limit`` (mm, deg, or a condition number)."""

    kind: str = Field(description="stroke_low, stroke_high, base_cone, platform_cone, pose_range or near_singular")
    value: float | None = Field(description="null when infinite (an exactly singular pose)")
    limit: float
    message: str
    leg: Leg | None = None
    axis: str | None = None


class ValidatePoseReply(OkReply):
    reachable: bool
    violations: list[Violation]
    leg_setpoints: LegValues = Field(description="sensor readings the pose needs, mm")
    jacobian_condition: float | None = Field(description="scaled Jacobian condition number; null if singular")


class MoveReply(OkReply):
    duration: float | None = Field(default=None, description="planned duration of the move, s")


class PlayReply(OkReply):
    sequence: SequenceProgress


class CalibrationReply(OkReply):
    calibration_id: str = Field(description="content hash of the geometry now active")
    name: str = Field(description="its name")


REPLY_MODELS: dict[str, type[OkReply]] = {
    "status": StatusReply,
    "validate_pose": ValidatePoseReply,
    "move": MoveReply,
    "play": PlayReply,
    "load_calibration": CalibrationReply,
    "rollback_calibration": CalibrationReply,
}
"""The reply model of each command whose reply carries more than :class:`OkReply`."""
