"""The API's messages as pydantic models: the user-facing contract (docs/api.md).

Every pose is ``[x, y, z, roll, pitch, yaw]`` in mm and degrees, relative to the zero
posture unless its frame says otherwise (``frame``, ``tool_pose_*``); leg values are actuator sensor readings in mm; times in s unless the name
says otherwise (``_us``: microseconds).

Requests are validated strictly (no coercion: ``"1"`` is not a number, ``true`` is not
an integer), extra keys are refused and floats must be finite. Replies and telemetry
are built by the service; their models exist so the schema documents them and tests
can check what is sent.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union, get_args

from pydantic import BaseModel, ConfigDict, Field, JsonValue, model_validator

from hexactl.adapters.api.protocol import MAX_DEADLINE_MS
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.sequences import Paced, SequenceWaypoint
from hexactl.kinematics.axes import FramePoseMmDeg, RelativeMmDeg, ToolInWorkMmDeg
from hexactl.kinematics.soft_limits import SoftLimits

LegValues = Annotated[list[float], Field(min_length=6, max_length=6, description="legs 1–6, sensor mm")]
LegReadings = Annotated[
    list[float | None], Field(min_length=6, max_length=6, description="legs 1–6, sensor mm; null for a leg not heard from yet")
]
Leg = Annotated[int, Field(ge=1, le=6, description="leg number 1–6")]
DeadlineMs = Annotated[
    float,
    Field(gt=0, le=MAX_DEADLINE_MS, description="carry it out within this many ms of the service receiving it, or not at all "
          "(expired); at most an hour"),
]
ErrorCodeText = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$", description="snake_case error code")]
RequestId = Annotated[JsonValue, Field(description="any JSON value; echoed in the reply")]
FilePath = Annotated[str, Field(min_length=1, max_length=4096, description="a file in the service's data directories")]
Point = Annotated[list[float], Field(min_length=3, max_length=3, description="[x, y, z], mm, fixed frame")]


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


# -- requests ------------------------------------------------------------------------


class _Request(_Message):
    v: Literal[1] = Field(description="protocol version")
    id: RequestId
    deadline_ms: DeadlineMs | None = None


class StatusRequest(_Request):
    """Reply with the current telemetry record."""

    cmd: Literal["status"]


class EnableRequest(_Request):
    """Energise the actuators; the platform holds the pose it is at."""

    cmd: Literal["enable"]


class DisableRequest(_Request):
    """De-energise the actuators (at rest only: stop first)."""

    cmd: Literal["disable"]


class StopRequest(_Request):
    """Brake smoothly to rest and stay enabled; ends a sequence."""

    cmd: Literal["stop"]


class EstopRequest(_Request):
    """Emergency stop, latched until ``reset``."""

    cmd: Literal["estop"]


class ResetRequest(_Request):
    """Clear a latched fault or emergency stop; ends disabled."""

    cmd: Literal["reset"]


FrameName = Annotated[Literal["zero", "work", "tool"], Field(
    description="zero: the platform relative to the zero posture (the default); work: the tool's pose in the work "
    "frame, rotations about the pivot point; tool: relative moves along and about the tool's own axes")]

_POSE_IN_FRAME = ("mm and deg: with frame zero relative to the zero posture, with work the tool's pose in the work "
                  "frame; with relative: true the displacement from where the motion is headed, in that frame")


class _PoseInFrame(_Request, Paced):
    pose: RelativeMmDeg = Field(description=_POSE_IN_FRAME)
    frame: FrameName = Frame.ZERO.value
    relative: bool = Field(default=False, description="pose is a displacement from the goal of the motion under way "
                           "(or the pose at rest): component by component in zero and work, composed in tool")


class MoveRequest(_PoseInFrame):
    """Move to ``pose`` in ``frame``, the whole path validated first (refused whole
    otherwise; soft limits too). A move while moving replaces the running one (in another
    frame: refused ``busy`` until at rest); in leg-lock mode the goal is projected so the
    locked leg keeps its length (the reply's ``goal``, relative to the zero posture)."""

    cmd: Literal["move"]


class ValidatePoseRequest(_PoseInFrame):
    """Would ``move`` accept this now? Plans and checks the whole path; moves nothing."""

    cmd: Literal["validate_pose"]


class SetFramesRequest(_Request):
    """Set the operator's work frame, tool frame (its origin is the pivot point) and soft
    limits; what is not given stays as it is. Saved, and restored when the service
    restarts. Refused (``outside_soft_limits``) when the pose being commanded breaks the
    new soft limits. A motion under way keeps the frames it was planned in."""

    cmd: Literal["set_frames"]
    work: FramePoseMmDeg | None = Field(default=None, description="the work frame in the zero frame, mm and deg")
    tool: FramePoseMmDeg | None = Field(default=None, description="the tool frame in the platform's frame, mm and deg")
    soft_limits: SoftLimits | None = Field(default=None, description="bounds on the tool's pose in the work frame "
                                           "(replaces all of them)")


class ClearFramesRequest(_Request):
    """Back to no work frame, no tool frame and no soft limits (saved)."""

    cmd: Literal["clear_frames"]


class FramesRequest(_Request):
    """Reply with the operator's frames and soft limits (``frames``)."""

    cmd: Literal["frames"]


class LegLockRequest(_Request):
    """Brake one leg at its current length; moves then keep it there (leg-lock mode)."""

    cmd: Literal["leg_lock"]
    leg: Leg


class LegUnlockRequest(_Request):
    """Release the locked leg."""

    cmd: Literal["leg_unlock"]


class Waypoint(_Message, SequenceWaypoint):
    """One waypoint of an inline sequence: the ``[[waypoint]]`` table of a sequence file
    (strict, as every message)."""


class InlineSequence(_Message):
    """A sequence given in the request, as a sequence file would give it."""

    name: str = Field(min_length=1, max_length=200)
    description: str = ""
    frame: Literal["zero", "work"] = Field(default="zero", description="the waypoints' poses: relative to the zero "
                                           "posture (zero), or the tool's poses in the work frame (work)")
    waypoints: list[Waypoint] = Field(min_length=1, max_length=1000)


class PlayRequest(_Request):
    """Play a sequence, every waypoint's path validated before the first moves."""

    cmd: Literal["play"]
    sequence: str | InlineSequence = Field(
        description="a built-in name (x_sweep, y_rotation, compound), a .toml sequence file or a .csv plan "
        "(from hexactl plan-leglock) in the data directories, or the sequence itself"
    )


class PauseRequest(_Request):
    """Pause the sequence: brake to rest mid-move, or freeze the dwell's clock."""

    cmd: Literal["pause"]


class ResumeRequest(_Request):
    """Continue the paused sequence."""

    cmd: Literal["resume"]


class AbortRequest(_Request):
    """End the sequence and brake to rest; its dwell records are kept."""

    cmd: Literal["abort"]


class LoadCalibrationRequest(_Request):
    """Switch to a calibration, ramped in; exactly one of ``path`` or ``toml`` (the file's
    text), and with ``toml`` optionally ``source``: where the text came from, recorded as
    the calibration's source (``request (SOURCE)``, telemetry's ``calibration_source``)."""

    cmd: Literal["load_calibration"]
    path: FilePath | None = None
    toml: str | None = None
    source: str | None = Field(None, min_length=1, max_length=4096, description="with toml: the sender's name for "
                               "the text, e.g. the file it read (default: request)")

    @model_validator(mode="after")
    def _exactly_one_source(self) -> LoadCalibrationRequest:
        if (self.path is None) == (self.toml is None):
            raise ValueError("give exactly one of path or toml")
        if self.source is not None and self.toml is None:
            raise ValueError("source names a toml text: give it with toml only")
        return self


class RollbackCalibrationRequest(_Request):
    """Return to the calibration active before the last load (ramped like a load)."""

    cmd: Literal["rollback_calibration"]


class SaveRecordingRequest(_Request):
    """Write the playing or last sequence's dwell records as CSV to a new file in a data directory."""

    cmd: Literal["save_recording"]
    path: FilePath


class MeasureRequest(_Request):
    """Measure the platform's feature points with the measuring instrument: the
    simulator's (``no_instrument`` when the service drives real actuators)."""

    cmd: Literal["measure"]


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
    SaveRecordingRequest,
    MeasureRequest,
    SetFramesRequest,
    ClearFramesRequest,
    FramesRequest,
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
    """The control loop's timing and health counters."""

    rate_hz: float = Field(description="loop rate, Hz")
    cycles: int = Field(description="cycles run since start")
    missed: int = Field(description="cycles that woke more than half a period late")
    skipped: int = Field(description="deadlines dropped after an overrun (the loop never bursts to catch up)")
    lateness_us: Percentiles = Field(description="wake-up lateness, µs")
    compute_us: Percentiles = Field(description="time from wake-up to the end of the cycle's work, µs")
    gc_runs: int = Field(description="young-generation garbage collections run in the loop's slack")
    gc_max_us: float = Field(description="the longest of them, µs")
    exchange_max_us: float = Field(
        description="the longest exchange with the API process (command intake, snapshot publication) in the "
        "loop's slack, µs"
    )
    guard_clamps: int = Field(description="cycles in which the set-point guard changed a set-point (should stay 0)")
    fk_failures: int = Field(description="cycles whose feedback had no forward-kinematics solution")


class RealtimeTelemetry(_Message):
    """What real-time set-up the loop obtained (``hexactl serve`` asks for SCHED_FIFO and locked memory by default)."""

    fifo_priority: int | None = Field(description="the loop thread's SCHED_FIFO priority; null: normal scheduling")
    cpus: list[int] | None = Field(description="CPUs the loop thread may run on; null: any")
    memory_locked: bool = Field(description="the loop's process memory is locked (mlockall)")
    switch_interval_s: float | None = Field(description="the loop process's GIL switch interval, s")
    gc_managed: bool = Field(description="the loop runs the garbage collector in its slack")
    notes: list[str] = Field(description="each real-time step left out or failed, with the reason")


class SequenceProgress(_Message):
    """The sequence being played."""

    name: str
    index: int = Field(ge=1, description="waypoint being approached or dwelt at, 1-based")
    total: int = Field(ge=1, description="number of waypoints")
    phase: str = Field(description="moving, dwelling, pausing or paused")


class Fault(_Message):
    """Why the controller latched FAULT or ESTOP."""

    code: ErrorCodeText
    message: str
    leg: Leg | None = Field(default=None, description="the actuator at fault, if one is")


class Telemetry(_Message):
    """One control cycle's picture."""

    t: float = Field(description="time of the cycle, s, on the service host's monotonic clock")
    state: str = Field(description="disabled, enabled, fault or estop")
    motion: str = Field(description="holding, moving or stopping")
    pose_command: RelativeMmDeg = Field(description="commanded pose")
    pose_measured: RelativeMmDeg | None = Field(description="pose from the actuators' feedback by forward kinematics; null if none")
    leg_setpoints: LegValues = Field(description="set-points sent, sensor mm")
    leg_feedback: LegReadings | None = Field(description="actuator positions reported, sensor mm; null before the first read")
    locked_leg: Leg | None = Field(description="the locked leg, or null")
    calibration_id: str = Field(description="content hash of the active geometry or calibration")
    sequence: SequenceProgress | None = Field(description="the sequence being played, or null")
    faults: list[Fault] = Field(description="why FAULT or ESTOP is latched; empty otherwise")
    loop: LoopTelemetry
    realtime: RealtimeTelemetry | None = Field(default=None, description="the loop's real-time set-up; null before it starts")
    goal: RelativeMmDeg | None = Field(
        default=None, description="where the move under way ends (projected onto the locked leg's constraint in leg-lock "
        "mode); null at rest and while braking")
    remaining_s: float | None = Field(
        default=None, ge=0, description="time until the move or the braking under way ends as planned, s; null at rest")
    tool_pose_command: ToolInWorkMmDeg | None = Field(default=None, description="pose_command as the tool's pose in "
                                                      "the work frame, mm and deg")
    tool_pose_measured: ToolInWorkMmDeg | None = Field(default=None, description="pose_measured as the tool's pose in "
                                                       "the work frame, mm and deg; null if none")
    frames: OperatorFrames | None = Field(default=None, description="the operator's frames and soft limits")


# -- replies -------------------------------------------------------------------------


class ErrorBody(_Message):
    code: ErrorCodeText
    message: str = Field(description="for people")
    details: JsonValue = Field(default=None, description="for programs, e.g. the violations of a path_violation")


class ErrorReply(_Message):
    """A refused or failed request. ``id`` is null when it could not be read from the request."""

    v: Literal[1]
    id: RequestId
    ok: Literal[False]
    error: ErrorBody


class OkReply(_Message):
    """A request carried out. ``message`` says what happened, for people."""

    v: Literal[1]
    id: RequestId
    ok: Literal[True]
    message: str = ""


class StatusReply(OkReply):
    status: Telemetry


class MoveReply(OkReply):
    goal: RelativeMmDeg = Field(description="the goal as planned, relative to the zero posture (projected onto the "
                                "locked leg's constraint in leg-lock mode)")
    tool_goal: ToolInWorkMmDeg | None = Field(default=None, description="for a move in the work or tool frame: the "
                                              "goal as the tool's pose in the work frame")
    duration: float = Field(description="planned duration, s")


class ValidatePoseReply(OkReply):
    valid: bool = Field(description="whether move would accept the pose now")
    goal: RelativeMmDeg | None = Field(description="the goal as planned, relative to the zero posture, when valid")
    tool_goal: ToolInWorkMmDeg | None = Field(default=None, description="for a move in the work or tool frame, when "
                                              "valid: the goal as the tool's pose in the work frame")
    duration: float | None = Field(description="planned duration, s, when valid")
    refusal: ErrorBody | None = Field(description="what move would answer, when not valid")


class PlayReply(OkReply):
    name: str
    waypoints: int = Field(description="number of waypoints")
    duration: float = Field(description="planned duration including dwells, s")


class CalibrationReply(OkReply):
    calibration_id: str = Field(description="content hash of the calibration being ramped in")
    change_mm: float = Field(description="the largest set-point change the swap makes at the current pose, mm")


class SaveRecordingReply(OkReply):
    path: str = Field(description="the file written, on the service's machine")
    name: str = Field(description="the sequence recorded")
    status: str = Field(description="playing, finished, aborted or fault")
    records: int = Field(description="rows written (one per dwell)")


class MeasureReply(OkReply):
    points: list[Point] = Field(
        description="the geometry's [measurement] feature points in their order, as measured in the fixed frame, mm "
        "(noise σ per coordinate: the geometry's point_sigma_mm unless the service sets another)"
    )


class FramesReply(OkReply):
    frames: OperatorFrames = Field(description="the operator's frames and soft limits now in force")


class PathViolation(_Message):
    """An item of ``error.details.violations`` (``path_violation``): the first sample of a
    waypoint's path that violates a limit."""

    waypoint: int = Field(ge=1, description="1-based waypoint whose path violates")
    pose: RelativeMmDeg = Field(description="the violating sample")
    kind: str = Field(description="stroke_low, stroke_high, base_cone, platform_cone, pose_range, near_singular, "
                      "soft_limit (an axis of the tool's pose in the work frame) or soft_tilt")
    message: str
    value: float | None = Field(description="the violating value (mm, deg or condition number); null if infinite")
    limit: float
    leg: Leg | None = None
    axis: str | None = None


REPLY_MODELS: dict[str, type[OkReply]] = {
    "status": StatusReply,
    "move": MoveReply,
    "validate_pose": ValidatePoseReply,
    "play": PlayReply,
    "load_calibration": CalibrationReply,
    "rollback_calibration": CalibrationReply,
    "save_recording": SaveRecordingReply,
    "measure": MeasureReply,
    "set_frames": FramesReply,
    "clear_frames": FramesReply,
    "frames": FramesReply,
}
"""The reply model of each command whose reply carries more than :class:`OkReply`."""
