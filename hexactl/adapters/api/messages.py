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

import re
from typing import Annotated, Any, Literal, Union, get_args

from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, JsonValue, TypeAdapter,
                      ValidatorFunctionWrapHandler, WrapValidator, model_validator)

from hexactl.adapters.api.protocol import (
    MAX_DEADLINE_MS,
    MAX_RECORDING_DIVISOR,
    MAX_RECORDING_S,
    RECORDING_EXTENSION_PATTERN,
    RECORDING_NAME_PATTERN,
)
from hexactl.control.core import KEPT_EVENTS
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.kinematics.one_line import ONE_LINE_PATTERN
from hexactl.control.planning import MAX_WAYPOINTS
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S
from hexactl.control.sequences import Paced, SequenceName, SequenceWaypoint
from hexactl.control.telemetry import TELEMETRY_EVENTS
from hexactl.control.validated_under import ValidatedUnder
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.axes import FramePoseMmDeg, RelativeMmDeg, ToolInWorkMmDeg
from hexactl.kinematics.soft_limits import SoftLimitChanges, SoftLimits

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
ExpiresAt = Annotated[
    float,
    Field(gt=0, description="carry it out before this Unix time (s, as time.time() gives it) by the service host's "
          "clock, or not at all (expired): the sender's own deadline, which holds however late the request reaches "
          "the service; client and service keep their clocks together (NTP)"),
]
ErrorCodeText = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$", description="snake_case error code")]
RequestId = Annotated[JsonValue, Field(description="any JSON value; echoed in the reply")]
MAX_READ_BYTES = 1024 * 1024
"""The most ``read_file`` returns per request (base64 makes the reply a third larger)."""

MAX_FILES_LISTED = 1000
"""The most files ``files`` lists."""


def _text_matching(pattern: str, rule: str, *lengths: Any) -> Any:
    """A string type that must match ``pattern`` (in the schema), refused saying ``rule``,
    what the text may contain: pydantic's own refusal quotes the regular expression.
    ``lengths``: a ``Field``'s length bounds, checked first (an empty text is empty, not "not allowed")."""
    compiled = re.compile(pattern)

    def check(text: str) -> str:
        if compiled.fullmatch(text) is None:
            raise ValueError(f"{text[:120]!r} is not allowed: {rule}")
        return text

    return Annotated[str, *lengths, AfterValidator(check), Field(json_schema_extra={"pattern": pattern})]


_RECORDING_EXTENSION = re.compile(RECORDING_EXTENSION_PATTERN)


def _no_extension(name: str) -> str:
    if _RECORDING_EXTENSION.search(name):
        raise ValueError(f"{name!r} is not allowed: a recording's name is given without extension (run1, not "
                         "run1.csv: .csv and .json are added)")
    return name


RecordingName = Annotated[
    _text_matching(RECORDING_NAME_PATTERN, "a recording's name is 1 to 100 letters, digits, '.', '_' or '-', "
                   "starting with a letter or digit (no directory; .csv and .json are added)"),
    AfterValidator(_no_extension), Field(json_schema_extra={"not": {"pattern": RECORDING_EXTENSION_PATTERN}})]
StreamSource = _text_matching(r"^[\x20-\x7e]+$", "the source is printable ASCII: letters, digits, spaces and punctuation")
OneLine = _text_matching(ONE_LINE_PATTERN, "one line of text, without control characters (no line end, no tab)")
"""Text the service's log writes (:mod:`hexactl.kinematics.one_line`)."""
ShownLine = _text_matching(ONE_LINE_PATTERN.replace("]+$", "]*$"), "one line of text, without control characters "
                           "(no line end, no tab, no escape sequence)")
"""Text telemetry carries to every display, and a terminal prints: one line, or none."""

FilePath = Annotated[
    _text_matching(ONE_LINE_PATTERN, "a path is one line of text, without control characters (a file named with a "
                   "line end or a tab: rename it)", Field(min_length=1, max_length=4096)),
    Field(description="a file in the service's data directories")]
"""The log writes it, as every name it writes: one line (:mod:`hexactl.kinematics.one_line`)."""
Point = Annotated[list[float], Field(min_length=3, max_length=3, description="[x, y, z], mm, fixed frame")]


def json_type(value: Any) -> str:
    """What a JSON value that is not an object is, for a refusal: "an array", "a string"…"""
    return {list: "an array", str: "a string", bool: "a boolean", type(None): "null"}.get(type(value), "a number")


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


# -- requests ------------------------------------------------------------------------


class _Request(_Message):
    v: Literal[1] = Field(description="protocol version")
    id: RequestId
    deadline_ms: DeadlineMs | None = None
    expires_at: ExpiresAt | None = None


class StatusRequest(_Request):
    """Reply with the current telemetry record."""

    cmd: Literal["status"]


class EventsRequest(_Request):
    """Reply with the loop's kept events numbered after ``after``, oldest first: send the
    last reply's ``last`` to have each event once (telemetry carries only the newest few)."""

    cmd: Literal["events"]
    after: int = Field(default=0, ge=0, description="the number (seq) of the last event already seen; 0: every "
                       "event the loop keeps")


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
    tolerance_mm: float | None = Field(default=None, gt=0, description="refuse (accuracy_insufficient) if the "
                                       "predicted 1σ position error at the tool point on arrival exceeds this, mm")
    validated_under: ValidatedUnder | None = Field(
        default=None, description="validate_pose's validated_under, sent back unchanged: refuse "
        "(changed_since_validation) if the frames, soft limits or calibration in force differ from these, or the "
        "move's goal from the goal validated (a relative move after the platform moved)")


class PredictedAccuracy(BaseModel):
    """The predicted 1σ error at the tool point (the tool frame's origin, the pivot; the
    platform's origin without a tool frame), from the active calibration's parameter
    covariance."""

    position_mm: float = Field(description="position error as a radius (RMS distance), √(σx² + σy² + σz²), mm: "
                               "not a per-axis σ (the calibration report's per-axis RMS is about 1/√3 of it)")
    position_axes_mm: tuple[float, float, float] = Field(description="σ along the zero frame's x, y, z, mm")
    orientation_deg: float = Field(description="orientation error as an angle (RMS rotation), √(σωx² + σωy² + "
                                   "σωz²) of the small rotation vector, deg")
    tool_point_mm: tuple[float, float, float] = Field(description="the point, in the platform's frame, mm")


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
    limits; what is not given stays as it is. The soft limits are replaced whole
    (``soft_limits``) or changed bound by bound, the others kept (``soft_limit_changes``:
    ``{"lower": {"x": -40}}``, ``{"max_tilt_deg": null}`` removes the tilt bound), against
    those in force when the service takes the request. Saved, and restored when the
    service restarts. At rest only (``busy`` while a motion, a sequence, paused too, a wave
    or a stream is under way: a motion keeps the frames it was planned in). Refused
    (``outside_soft_limits``) when the pose being commanded breaks the new soft limits."""

    cmd: Literal["set_frames"]
    work: FramePoseMmDeg | None = Field(default=None, description="the work frame in the zero frame, mm and deg")
    tool: FramePoseMmDeg | None = Field(default=None, description="the tool frame in the platform's frame, mm and deg")
    soft_limits: SoftLimits | None = Field(default=None, description="bounds on the tool's pose in the work frame "
                                           "(replaces all of them)")
    soft_limit_changes: SoftLimitChanges | None = Field(default=None, description="bounds to change, by name; the "
                                                        "others kept")

    @model_validator(mode="after")
    def _one_way_to_set_soft_limits(self) -> SetFramesRequest:
        if self.soft_limits is not None and self.soft_limit_changes is not None:
            raise ValueError("soft_limits replaces all of them and soft_limit_changes some: give one, not both")
        return self


class ClearFramesRequest(_Request):
    """Back to no work frame, no tool frame and no soft limits (saved)."""

    cmd: Literal["clear_frames"]


class FramesRequest(_Request):
    """Reply with the operator's frames and soft limits (``frames``)."""

    cmd: Literal["frames"]


JogVelocity = Annotated[list[float], Field(
    min_length=6, max_length=6,
    description="x, y, z in mm/s and roll, pitch, yaw in deg/s, in the frame; all zeros release the jog")]


class JogRequest(_Request):
    """Jog at ``velocity`` in ``frame`` while this request is repeated: send it again at
    least every ``jog_deadman_s`` (0.2 s by default; ``status`` says) or the platform
    brakes to rest along its path. The same velocity and frame renew the jog under way,
    another velocity re-plans it, all zeros release it. The jog heads for the first limit
    ahead (hardware or soft) and comes to rest on it: it is not refused there. A renewal
    that names its jog (``renews``) is refused ``jog_ended`` once that jog has ended
    (a ``stop`` from anyone, a lapse, a fault), instead of starting a new one; after a
    lapse, ``restarts`` starts a new one unless anything came after the lapse."""

    cmd: Literal["jog"]
    velocity: JogVelocity
    frame: FrameName = Frame.ZERO.value
    renews: int | None = Field(default=None, ge=1, description="the number of the jog this request renews (the reply "
                               "that started it says it): refused jog_ended once that jog has ended, so that a stop "
                               "from anyone ends a held jog for good; without it, a jog after the end of the last "
                               "starts a new one")
    restarts: int | None = Field(default=None, ge=1, description="the number of a jog whose deadman lapsed (its "
                                 "renewal was refused jog_ended with details.lapsed true): a new jog in its place, "
                                 "refused jog_ended (lapsed false) if anything came after the lapse, a stop from "
                                 "anyone; not with renews")


class _WaveBody(_Request, WaveSpec):
    pass


class WaveRequest(_WaveBody):
    """Play a wave from rest: each axis in ``axes`` oscillates as ``amplitude·sin(2π·
    frequency_hz·t + phase_deg)`` about the start pose in ``frame`` for ``cycles``
    periods, ramped in and out over ``ramp_cycles``. The whole path is validated first
    (stroke, cones, envelope, soft limits, the legs' speed, the motion limits): a wave too
    fast is refused, never slowed down. ``stop`` or ``abort`` brake it to rest; it cannot
    be paused."""

    cmd: Literal["wave"]


class ValidateWaveRequest(_WaveBody):
    """Would ``wave`` accept this now? Plans and checks the whole path; moves nothing."""

    cmd: Literal["validate_wave"]


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

    name: SequenceName
    description: str = ""
    frame: Literal["zero", "work"] = Field(default="zero", description="the waypoints' poses: relative to the zero "
                                           "posture (zero), or the tool's poses in the work frame (work)")
    waypoints: list[Waypoint] = Field(min_length=1, max_length=MAX_WAYPOINTS)


_SEQUENCE_NAME = TypeAdapter(FilePath)


def _named_or_given(value: Any, union: ValidatorFunctionWrapHandler) -> str | InlineSequence:
    """A sequence's name or the sequence, told apart by the JSON type, so that a mistake in
    one is refused as that one (pydantic's union refused both: ``sequence.str: Input should
    be a valid string; sequence.InlineSequence.waypoints.0.duration: …``)."""
    if isinstance(value, dict):
        return InlineSequence.model_validate(value)  # its problems are told at sequence.…
    if isinstance(value, str):
        return _SEQUENCE_NAME.validate_python(value)
    if isinstance(value, InlineSequence):
        return union(value)
    raise ValueError(f"a sequence is its name (a string) or the sequence itself (an object), got {json_type(value)}")


class PlayRequest(_Request):
    """Play a sequence, every waypoint's path validated before the first moves."""

    cmd: Literal["play"]
    sequence: Annotated[FilePath | InlineSequence, WrapValidator(_named_or_given)] = Field(
        description="a built-in name (x_sweep, y_rotation, compound), a .toml sequence file or a .csv plan "
        "(from hexactl plan-leglock) in the data directories, or the sequence itself"
    )


class ValidateSequenceRequest(PlayRequest):
    """Would ``play`` accept this sequence? Plans and checks every waypoint's path from
    where the move under way ends, at rest (disabled: where the platform is); moves nothing."""

    cmd: Literal["validate_sequence"]  # type: ignore[assignment]


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
    the calibration's source (``request (SOURCE)``, telemetry's ``calibration_source``).
    Optionally ``expected_id``: the id a preview (``validate_calibration``) answered; the
    file or text read now must hold that calibration, or nothing is loaded."""

    cmd: Literal["load_calibration"]
    path: FilePath | None = None
    toml: str | None = None
    source: OneLine | None = Field(None, max_length=4096, description="with toml: the sender's name for the text, "
                                   "e.g. the file it read (default: request)")
    expected_id: str | None = Field(
        None, min_length=1, max_length=64, pattern=r"^[!-~]+$",
        description="the calibration id the sender previewed (validate_calibration's calibration_id): refused "
        "(changed_since_validation), nothing loaded, if the file or text read now holds another calibration")

    @model_validator(mode="after")
    def _exactly_one_source(self) -> LoadCalibrationRequest:
        if (self.path is None) == (self.toml is None):
            raise ValueError("give exactly one of path or toml")
        if self.source is not None and self.toml is None:
            raise ValueError("source names a toml text: give it with toml only")
        return self


class ParameterEstimate(_Message):
    name: ShownLine = Field(max_length=40, description="B1.x … P6.z (joints, mm), zero1 … (zero lengths, mm), scale1 … "
                      "(sensor scale errors)")
    value: float
    sigma: float | None = Field(description="1σ, same unit; null when not determined")


class MotionErrors(_Message):
    motion: ShownLine = Field(max_length=100, description="the test motion")
    before_position_mm: float = Field(description="largest position error before calibration, mm")
    before_orientation_deg: float = Field(description="largest orientation error before calibration, deg")
    after_position_mm: float = Field(description="largest position error after calibration, mm")
    after_orientation_deg: float = Field(description="largest orientation error after calibration, deg")


class CampaignReport(_Message):
    """A finished campaign's results, for displays."""

    method: ShownLine = Field(max_length=40)
    calibration_id: ShownLine = Field(max_length=64)
    postures: int = Field(ge=0)
    residual_rms_mm: float
    expected_rms_mm: float = Field(description="the noise model's expectation of the residual RMS, mm")
    fit: ShownLine = Field(max_length=200, description="the χ²/dof sentence")
    parameters: list[ParameterEstimate] = Field(max_length=60)
    validation: list[MotionErrors] = Field(max_length=20, description="each test motion before and after")
    improved: bool
    warnings: list[Annotated[ShownLine, Field(max_length=1000)]] = Field(default=[], max_length=20)


class ProgressRequest(_Request):
    """A client's campaign says how far it is (a phase's steps, a sentence it printed, its
    report when finished); telemetry's ``campaign`` carries the latest to every display."""

    cmd: Literal["progress"]
    title: OneLine = Field(max_length=200, description="the phase, e.g. postures")
    done: int = Field(ge=0, description="steps of the phase done")
    total: int = Field(ge=0, description="steps of the phase")
    label: ShownLine = Field(default="", max_length=200, description="the latest step, e.g. leg 3 locked")
    said: OneLine | None = Field(default=None, min_length=1, max_length=2000, description="a sentence the campaign printed (a "
                                 "line of it)")
    report: CampaignReport | None = Field(default=None, description="the finished campaign's results")

    @model_validator(mode="after")
    def _done_within_total(self) -> ProgressRequest:
        if self.done > self.total:
            raise ValueError(f"done ({self.done}) is more than total ({self.total})")
        return self


class ValidateCalibrationRequest(LoadCalibrationRequest):
    """Would ``load_calibration`` accept it now? The same fields and checks; nothing is
    swapped. The reply says the set-point change the load would make."""

    cmd: Literal["validate_calibration"]  # type: ignore[assignment]


class GeometryRequest(_Request):
    """The geometry the loop runs now (calibrated or nominal): joints, zero lengths,
    sensor gains, zero posture, limits and feature points, for a client that draws or
    checks the platform."""

    cmd: Literal["geometry"]


class FilesRequest(_Request):
    """The files directly in the service's data directories, with what each holds."""

    cmd: Literal["files"]


class ReadFileRequest(_Request):
    """A chunk of a file in the data directories (a recording to download), base64."""

    cmd: Literal["read_file"]
    path: FilePath
    offset: int = Field(default=0, ge=0, description="the first byte to read")
    length: int = Field(default=MAX_READ_BYTES, ge=1, le=MAX_READ_BYTES, description="at most this many bytes")


class RollbackCalibrationRequest(_Request):
    """Return to the calibration active before the last load (ramped like a load)."""

    cmd: Literal["rollback_calibration"]


class SaveRecordingRequest(_Request):
    """Write the playing or last sequence's dwell records as CSV to a new file in a data directory."""

    cmd: Literal["save_recording"]
    path: FilePath


RecordSignal = Literal["pose_command", "pose_measured", "setpoints", "feedback", "lateness", "compute"]


class RecordRequest(_Request):
    """Record signals of the control loop to ``NAME.csv`` (and its side file ``NAME.json``)
    in the first data directory: every ``divisor``-th cycle for ``duration_s``, from now
    or from the next motion's start. One recording at a time (not ``save_recording``,
    which saves a sequence's dwell records)."""

    cmd: Literal["record"]
    name: RecordingName = Field(description="the files' name without extension: a bare file name, no directory")
    signals: list[RecordSignal] = Field(
        default=["pose_command", "pose_measured", "setpoints", "feedback", "lateness", "compute"], min_length=1,
        description="what to record (default: all): pose_command and pose_measured (mm, deg, in frame), setpoints "
        "and feedback (legs, sensor mm), lateness and compute (the loop's, µs)")
    frame: Literal["zero", "work"] = Field(default="zero", description="the poses' frame: zero (relative to the zero "
                                           "posture) or work (the tool's pose in the work frame at the start)")
    divisor: int = Field(default=1, ge=1, le=MAX_RECORDING_DIVISOR,
                         description="record every divisor-th cycle (1: every cycle)")
    duration_s: float = Field(gt=0, le=MAX_RECORDING_S, description="how long to record, s (at most an hour)")
    start: Literal["now", "next_motion"] = Field(default="now", description="now, or armed until the next move, "
                                                 "sequence or other motion starts")


class RecordStopRequest(_Request):
    """End the recording under way early; the reply comes once its files are written."""

    cmd: Literal["record_stop"]


class RecordStatusRequest(_Request):
    """The data recorder's writer: the recording being written, or the last one written."""

    cmd: Literal["record_status"]


class StreamOpenRequest(_Request):
    """Open a pose stream: from now on target poses sent to the stream socket (ZeroMQ
    PUSH, or UDP when the service listens for it; the reply's ``endpoints``) are followed
    by the loop, jerk-limited, each target out of reach replaced by the nearest reachable
    pose on the way to it. At rest, enabled, all six legs. If no target comes for
    ``timeout_ms`` the platform brakes to rest and the stream ends. One stream at a time;
    ``stream_close``, ``stop`` and ``estop`` end it (docs/stream.md)."""

    cmd: Literal["stream_open"]
    source: StreamSource = Field(min_length=1, max_length=64,
                                 description="who sends the stream, for people (printable ASCII)")
    frame: Literal["zero", "work"] = Field(default="zero", description="the targets' frame: zero (relative to the "
                                           "zero posture) or work (the tool's pose in the work frame)")
    # No lower bound of its own: the loop's, 3 of its cycles, is the one rule (stream_commands).
    timeout_ms: float = Field(default=100.0, gt=0.0, le=10_000.0,
                              description="the stream ends, braking to rest, when no target comes for this long; "
                              "at least 3 cycles of the loop (6 ms at 500 Hz): a shorter one is refused, naming "
                              "the least")


class StreamCloseRequest(_Request):
    """End the pose stream: the platform brakes to rest."""

    cmd: Literal["stream_close"]


class MeasureRequest(_Request):
    """Measure the platform's feature points with the measuring instrument: the
    simulator's (``no_instrument`` when the service drives real actuators)."""

    cmd: Literal["measure"]


REQUEST_MODELS: tuple[type[_Request], ...] = (
    StatusRequest,
    EventsRequest,
    EnableRequest,
    DisableRequest,
    StopRequest,
    EstopRequest,
    ResetRequest,
    MoveRequest,
    ValidatePoseRequest,
    JogRequest,
    WaveRequest,
    ValidateWaveRequest,
    LegLockRequest,
    LegUnlockRequest,
    PlayRequest,
    ValidateSequenceRequest,
    PauseRequest,
    ResumeRequest,
    AbortRequest,
    LoadCalibrationRequest,
    RollbackCalibrationRequest,
    SaveRecordingRequest,
    MeasureRequest,
    RecordRequest,
    RecordStopRequest,
    RecordStatusRequest,
    SetFramesRequest,
    ClearFramesRequest,
    FramesRequest,
    ValidateCalibrationRequest,
    GeometryRequest,
    FilesRequest,
    ReadFileRequest,
    ProgressRequest,
    StreamOpenRequest,
    StreamCloseRequest,
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
    report_age_s: float = Field(description="how long ago the loop's process sent what this record says, s: its "
                                "reports come every 10 ms at most; beyond 1 s (REPORT_SILENT_S) the loop's process is "
                                "stopped or hung, and the record is that old")


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


class LegStatus(_Message):
    """One actuator as it last reported."""

    state: Literal["disabled", "enabled", "locked", "fault", "estop"] = Field(description="what it reports it is doing")
    fault_bits: int = Field(ge=0, description="its drive's latched fault word (docs/can.md, FEEDBACK); 0: none")
    fault_names: list[str] = Field(description="the names of the bits set in fault_bits, lowest bit first, as "
                                   "firmware_proto/PROTOCOL.md section 9 spells them, in lower case (sensor, "
                                   "limit_switch, …); bit_N for a bit it does not define; empty: none")
    report_age_s: float | None = Field(ge=0, description="time since its last report, s; null: never heard from")


class OtherController(_Message):
    """Another controller heard on the CAN bus, driving the same actuators."""

    frame: str = Field(description="the kind of its last frame heard, as firmware_proto/PROTOCOL.md names it: "
                       "SETPOINT_12, SETPOINT_34, SETPOINT_56, SETPOINT_ALL_FD, SYNC or CMD_n and the command "
                       "(CMD_3 ENABLE); an E-stop frame is not counted (a safety PLC or an E-stop node may send one)")
    age_s: float = Field(ge=0, description=f"how long ago, s; within {OTHER_CONTROLLER_WINDOW_S:g} s enable is refused "
                         "(other_controller) and, enabled, FAULT other_controller is latched and the E-stop sent")


class LinkTelemetry(_Message):
    """The link to the actuators (the CAN bus), as the loop last read it."""

    bus_state: Literal["active", "warning", "passive", "bus_off", "down"] = Field(
        description="in CAN's error-state terms: active (healthy), warning (error counters high, still working), "
        "passive (error passive, still working, degraded: look at the wiring and termination), bus_off (this "
        "controller has left the bus: nothing is sent) or down (the interface is closed or missing); bus_off and "
        "down latch FAULT link_failed while enabled and refuse enable")
    send_failures: int = Field(ge=0, description="frames the link could not send (set-points, commands, E-stops) "
                               "since it was opened; 0 normally: a count that grows means a full transmit queue or "
                               "a failing interface")
    detail: str = Field(description="the link's note for people: silent legs, a leg that has restarted or speaks "
                        "another protocol version, two nodes with one id, the last driver error; empty: none")


class RecordingFileTelemetry(_Message):
    """What the writer's side file says of a recording the loop has done with."""

    ended: str = Field(description="as the side file's ended: duration, stopped, shutdown, fault or write_failed "
                       "(the rows are not all in the file: record_status's write_error says why)")
    faults_during: bool = Field(description="the controller was in FAULT or ESTOP during the recording")


class RecorderTelemetry(_Message):
    """The data recorder as the loop sees it, and, once written, what its file says
    (the whole side file: ``record_status``)."""

    state: Literal["idle", "armed", "recording", "done"]
    name: str = Field(description="the recording's name")
    rows: int = Field(ge=0, description="rows recorded so far")
    rows_requested: int = Field(ge=0, description="rows the recording asked for")
    lost: int = Field(ge=0, description="rows lost for want of room (the writer fell behind); 0 normally")
    ended: Literal["duration", "stopped"] | None = Field(description="how it ended, once done")
    file: RecordingFileTelemetry | None = Field(default=None, description="once done and its file written, what "
                                                "the side file says of it (found from outside: status said done, "
                                                "duration, of a recording whose file failed or saw a fault)")


class WaveTelemetry(_Message):
    """The wave playing, or the last one."""

    cycle: int = Field(ge=1, description="the wave's period under way (or the last reached), 1-based")
    cycles: int = Field(ge=1, description="the wave's periods")
    phase: Literal["ramp_in", "steady", "ramp_out", "finished", "aborted", "fault"] = Field(
        description="ramp_in, steady or ramp_out while it plays; how it ended: finished (at rest on the start pose), "
        "aborted (by stop or abort: braked to rest) or fault (a fault, an E-stop or a disable froze it)")


JOG_SPEED = ("its velocity scale, as a move's speed: the fraction of the motion's velocity limits it runs at, "
             "that of the velocity asked (1: the limits, when the velocity asked reaches them)")


class JogTelemetry(_Message):
    """The jog under way."""

    jog: int = Field(description="its number (the reply to the jog that started it says it)")
    frame: FrameName
    velocity: JogVelocity
    speed: float = Field(gt=0, le=1, description=JOG_SPEED)
    phase: Literal["jogging", "at_end", "braking"] = Field(
        description="jogging; at_end: at rest where its plan ends (on a limit, or at the horizon a renewal extends); "
        "braking: released, replaced or lapsed, braking to rest")
    end: str = Field(description="where its plan ends: the limit ahead, by name, or the horizon")
    to_limit: bool = Field(description="its plan ends on a limit (false: at the horizon)")
    renew_within_s: float = Field(ge=0, description="time left before the deadman lapses unless the jog is renewed, s")


class StreamTelemetry(_Message):
    """The pose stream under way, as the loop follows it."""

    stream: int = Field(description="its number (stream_open's reply says it)")
    source: str = Field(description="who sends it, as stream_open named it")
    frame: Literal["zero", "work"] = Field(description="the targets' frame")
    phase: Literal["following", "braking"] = Field(description="following the newest target; braking: timed out, "
                                                   "stopped or closed, braking to rest, then it ends")
    timeout_s: float = Field(description="it ends when no target comes for this long, s")
    targets: int = Field(ge=0, description="targets the loop took")
    last_sequence: int | None = Field(description="the sender's number of the newest target taken")
    since_target_s: float = Field(ge=0, description="time since the loop took the newest target, s")
    latency_ms: float | None = Field(description="from the newest target's arrival to the loop cycle that took it, ms")


class JogEnd(_Message):
    """How the last jog ended."""

    jog: int = Field(description="its number")
    reason: str = Field(description="why, for people: the deadman lapsed, released, replaced by a move, a fault, …")


class SequenceEnd(_Message):
    """The sequence playing, or how the last one ended."""

    name: str = Field(description="its name")
    status: Literal["playing", "finished", "aborted", "fault"] = Field(
        description="playing; or finished (every waypoint played), aborted (by stop, abort or a disable) or fault (a "
                    "fault or an E-stop ended it)")
    records: int = Field(ge=0, description="dwell records taken: the waypoints it played to the end of their dwell")


class StreamEnd(_Message):
    """How the last pose stream ended."""

    stream: int = Field(description="its number")
    reason: str = Field(description="why, for people: closed by the client, stopped, a timeout, a fault or E-stop, …")
    targets: int = Field(ge=0, description="targets the loop took")


class StreamPercentiles(_Message):
    p50: float
    p99: float
    max: float
    count: int = Field(ge=1, description="samples they are over")


class StreamInputTelemetry(_Message):
    """What the pose stream's receiver counted since the current (or last) stream opened."""

    running: bool = Field(description="the input takes samples; false: it stopped (the service's log says why) and "
                          "stream_open is refused until the service restarts")
    stream: int | None = Field(description="the stream the counts are for: the one open, or the last once it "
                               "closed (telemetry's stream says whether one is open); null before the first")
    received: int = Field(ge=0, description="messages read, well formed or not")
    malformed: int = Field(ge=0, description="not a sample (docs/stream.md), dropped")
    out_of_order: int = Field(ge=0, description="a sequence not above the last one taken: reordered or duplicated, "
                              "dropped")
    other_sender: int = Field(ge=0, description="samples from another sender than the stream's (the first UDP "
                              "address, or ZeroMQ, to send 3 of the stream's last 8 samples), once it is found: "
                              "dropped")
    no_stream: int = Field(ge=0, description="well formed, but no stream was open: dropped")
    coalesced: int = Field(ge=0, description="superseded by a newer sample before the loop's next cycle (not lost: "
                           "the newest wins)")
    forwarded: int = Field(ge=0, description="handed to the loop")
    clamped: int = Field(ge=0, description="of those, out of reach (or their way from the last one) and replaced by "
                         "the last reachable pose on the way")
    loop_behind: int = Field(ge=0, description="dropped on the way to the loop, which was behind reading its commands "
                             "(they waited unread in its pipe: it would have read the target stale, and an E-stop "
                             "behind it); the next target replaces it. Not counted in forwarded")
    failed: int = Field(ge=0, description="could not be handed to the loop (an error, in the service's log)")
    last_problem: str = Field(description="the last problem with a message (malformed, or an error taking it), or "
                              "empty")
    rate_hz: int = Field(ge=0, description="samples taken over the last second")
    loop_latency_ms: StreamPercentiles | None = Field(description="arrival → the loop cycle whose set-points carry it")
    age_ms: StreamPercentiles | None = Field(description="the sender's sent_s → arrival: meaningful only when the "
                                             "sender stamps with this host's CLOCK_MONOTONIC")


class CampaignTelemetry(_Message):
    """The latest a client's campaign said (``progress``), for every display."""

    title: str = Field(description="the phase")
    done: int
    total: int
    label: str
    said: list[str] = Field(description="the campaign's latest sentences, oldest first (at most 12, and 4000 "
                            "characters with the newest whole)")
    report: CampaignReport | None = Field(description="the finished campaign's results, once it has them")
    age_s: float = Field(description="seconds since the campaign last said something")


class LoopEvent(_Message):
    """Something the loop did or refused."""

    seq: int = Field(description="its number: the loop's first event is 1, each next one more (a gap: events the "
                     "reader missed; fewer than the last seen: the service has restarted, as the events reply's run says)")
    t: float = Field(description="when, s, on the clock of the record's t")
    code: str = Field(description="what, snake_case: a command carried out (enabled, disabled, stop, reset, move, "
                      "leg_locked, leg_unlocked, pause, resume, abort, wave_started, stream_closed, jog_released, frames_set: the "
                      "operator's frames and soft limits now), one that started something "
                      "(sequence_started, jog_started, stream_opened, calibration_swapped), estop, a fault's code, "
                      "command_refused, the end of something (sequence_*, wave_*: finished, aborted or fault, jog_ended, "
                      "stream_ended), "
                      "command_link_silent, …")
    message: str = Field(description="for people")
    sender: str | None = Field(description="who sent the command it carried out or refused: the name its client gave "
                               "(the X-Client connection property), then its address, or its process and user on "
                               "the service's host, and with CURVE its key's name; null: the loop's own doing")


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
    last_sequence: SequenceEnd | None = Field(default=None, description="the sequence playing, or how the last one "
                                              "ended; null before the first")
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
    outside_soft_limits: list[str] = Field(default=[], description="the soft limits the commanded pose breaks, one "
                                           "sentence each (a service started with the platform outside the soft limits "
                                           "it restored); empty inside them")
    recording: RecorderTelemetry | None = Field(default=None, description="the data recorder in the loop; null before "
                                                "the first recording")
    wave: WaveTelemetry | None = Field(default=None, description="the wave playing, or how the last one ended; null "
                                       "before the first wave")
    jog: JogTelemetry | None = Field(default=None, description="the jog under way; null when none is")
    last_jog: JogEnd | None = Field(default=None, description="how the last jog ended; null before the first")
    stream: StreamTelemetry | None = Field(default=None, description="the pose stream under way; null when none is")
    last_stream: StreamEnd | None = Field(default=None, description="how the last pose stream ended; null before "
                                          "the first")
    stream_input: StreamInputTelemetry | None = Field(default=None, description="the pose stream's receiver; null "
                                                      "in a service without one")
    campaign: CampaignTelemetry | None = Field(default=None, description="the latest a client's campaign said "
                                               "(progress); null before any")
    legs: list[LegStatus] | None = Field(default=None, min_length=6, max_length=6,
                                         description="legs 1–6 as each last reported: a fault that outlasts a reset "
                                         "shows here; null before the first read")
    events: list[LoopEvent] = Field(default_factory=list, max_length=TELEMETRY_EVENTS,
                                    description="the loop's latest events, oldest first (a burst of more: the events request "
                                    "has them)")
    other_controller: OtherController | None = Field(
        default=None, description="another controller last heard on the bus (another hexactl serve or a vendor tool "
        "on the same actuators); null: none since the service started")
    link: LinkTelemetry | None = Field(default=None, description="the link to the actuators: bus state, send "
                                       "failures and its note; null before the first read")
    run: str | None = Field(default=None, max_length=16, description="this run of the service, as the events reply's: "
                            "the same in its telemetry and its status, so a client that reads the one and commands "
                            "through the other can tell that both are one service; null: an older service's")


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
    calibration_source: str = Field(description="where the calibration in force (status.calibration_id) was read "
                                    "from: a file, or request (SOURCE) for one a client sent as text")
    calibration_warnings: list[str] = Field(
        default_factory=list, description="what the identification of the calibration in force warned of (its "
        "file's [calibration] warnings: a weakly determined one says so here); empty for a geometry file")
    predicted_accuracy: PredictedAccuracy | None = Field(
        default=None, description="at the commanded pose now; null without a calibration covariance")


class EventsReply(OkReply):
    t: float = Field(description="when the loop's events were read, s, on the clock of the events' t")
    events: list[LoopEvent] = Field(max_length=KEPT_EVENTS, description="the loop's kept events numbered after "
                                    "the request's after, oldest first")
    missed: int = Field(description=f"events numbered after the request's after that the loop no longer keeps (it "
                        f"keeps its latest {KEPT_EVENTS}): read at least every few seconds to miss none")
    last: int = Field(description="the newest event's number (0: none yet); send it as after to read on")
    run: str = Field(max_length=16, description="this run of the service: another than the last reply's means it "
                     "restarted, its events numbered from 1 again (read them with after 0)")


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
    predicted_accuracy: PredictedAccuracy | None = Field(
        default=None, description="at the goal, when valid; null without a calibration covariance")
    refusal: ErrorBody | None = Field(description="what move would answer, when not valid")
    validated_under: ValidatedUnder | None = Field(
        default=None, description="when valid: the calibration and the frames it was validated under and its goal; "
        "send it with the move to have the move refused if any of them changed meanwhile")


class JogReply(OkReply):
    jog: int | None = Field(description="the jog's number (null when the reply releases one)")
    goal: RelativeMmDeg | None = Field(description="where its plan ends, relative to the zero posture; null on a "
                                       "renewal or a release")
    speed: float | None = Field(description=JOG_SPEED)
    end: str | None = Field(description="where its plan ends: the limit ahead by name, or the horizon")
    to_limit: bool | None = Field(description="its plan ends on a limit (false: at the horizon a renewal extends)")
    deadman_s: float | None = Field(description="renew the jog at least this often, s")


class StreamEndpoints(_Message):
    zmq: str = Field(description="connect a ZeroMQ PUSH socket here and send samples (docs/stream.md); a wildcard "
                     "host (0.0.0.0) means the API's host")
    udp: str | None = Field(description="HOST:PORT where samples are also taken as UDP datagrams; null: no UDP")


class StreamOpenReply(OkReply):
    stream: int = Field(description="the stream's number")
    velocity_scale: float = Field(gt=0, le=1, description="the fraction of the stream's velocity limits available "
                                  "in every direction at once where it starts; along the way the stream moves, its "
                                  "targets may go faster, up to the legs' speed")
    endpoints: StreamEndpoints = Field(description="where to send the samples")


LOCK_CORRECTIONS = ("in leg-lock mode, how far each waypoint's goal is moved, in order, to the nearest pose that "
                    "keeps the locked leg's length, mm (rotations counted at the platform's characteristic length, "
                    "as lock_max_correction_mm counts them); null with no leg locked")


class PlayReply(OkReply):
    name: str
    waypoints: int = Field(description="number of waypoints")
    duration: float = Field(description="planned duration including dwells, s")
    lock_corrections_mm: list[float] | None = Field(default=None, description=LOCK_CORRECTIONS)


class ValidateSequenceReply(OkReply):
    valid: bool = Field(description="whether play would accept its paths now (play also needs the controller "
                        "enabled and at rest)")
    name: str = Field(description="the sequence's name")
    waypoints: int = Field(description="number of waypoints")
    duration: float | None = Field(description="planned duration including dwells, s, when valid")
    goal: RelativeMmDeg | None = Field(description="where the last waypoint ends, relative to the zero posture, when "
                                       "valid")
    lock_corrections_mm: list[float] | None = Field(description=LOCK_CORRECTIONS + " or not valid")
    refusal: ErrorBody | None = Field(description="what play would answer, when not valid")


CalibrationWarnings = Annotated[list[str], Field(
    description="what the identification that wrote the calibration warned of (its [calibration] table's warnings: "
                "weakly determined, the instrument's frame, the noise figures): read them before moving on it; empty: "
                "none, a geometry file, or a calibration written before they were kept")]


class CalibrationReply(OkReply):
    calibration_id: str = Field(description="content hash of the calibration being ramped in")
    change_mm: float = Field(description="the largest set-point change the swap makes at the current pose, mm (0 when "
                             "not enabled: nothing is ramped)")
    warnings: CalibrationWarnings = []


class ValidateCalibrationReply(OkReply):
    valid: bool = Field(description="whether load_calibration would accept it now")
    calibration_id: str | None = Field(description="its content hash, when valid")
    change_mm: float | None = Field(description="the largest set-point change the load would make now, mm, when valid "
                                    "(0 when not enabled: nothing is ramped)")
    refusal: ErrorBody | None = Field(description="what load_calibration would answer, when not valid")
    warnings: CalibrationWarnings = []


class GeometryReply(OkReply):
    calibration_id: str = Field(description="content hash of the active geometry")
    source: str = Field(description="where it was read from")
    geometry: dict[str, Any] = Field(description="the geometry as its file holds it (the keys of a calibration "
                                     "file: base_joints and platform_joints in mm, the fixed and the platform frame; "
                                     "zero_lengths mm; sensor_scale_errors; home mm and deg; limits; measurement), "
                                     "without the calibration's covariance")


class DataFile(_Message):
    name: str = Field(description="the file's name in its directory")
    directory: str = Field(description="the data directory, on the service's machine")
    kind: Literal["calibration", "sequence", "recording", "other"] = Field(
        description="calibration (a geometry TOML), sequence (a TOML with [[waypoint]], or a posture plan's CSV: "
        "play takes both), recording (the data recorder's CSV) or other")
    size: int = Field(description="bytes")
    modified: float = Field(description="last change, s since the epoch")


class FilesReply(OkReply):
    files: list[DataFile] = Field(description="each data directory's files, in order, by name")


class ReadFileReply(OkReply):
    path: str = Field(description="the file read, on the service's machine")
    offset: int
    data_b64: str = Field(description="the bytes read, base64")
    size: int = Field(description="the file's size, bytes")
    eof: bool = Field(description="true when the chunk reaches the end of the file")


class SaveRecordingReply(OkReply):
    path: str = Field(description="the file written, on the service's machine")
    name: str = Field(description="the sequence recorded")
    status: str = Field(description="playing, finished, aborted or fault")
    records: int = Field(description="rows written (one per dwell)")


class RecordReply(OkReply):
    path: str = Field(description="the CSV file, on the service's machine (written as NAME.csv.partial until the "
                      "recording ends)")
    side_file: str = Field(description="the JSON side file written at the end")
    rows: int = Field(description="rows the recording will have")
    rate_hz: float = Field(description="rows per second: the loop's rate over the divisor")
    duration: float = Field(description="the duration recorded, s (rows over rate)")


class RecordingSideFile(_Message):
    """The JSON side file of a recording (``NAME.json``), also the reply of ``record_stop``
    and, once written, of ``record_status``."""

    name: str
    csv: str = Field(description="the CSV file written")
    signals: list[str]
    frame: Literal["zero", "work"]
    frames: OperatorFrames | None = Field(description="with frame work: the operator's frames at the start")
    divisor: int
    loop_rate_hz: float
    rate_hz: float
    duration_s: float = Field(description="the duration asked for, s")
    start: Literal["now", "next_motion"]
    calibration_id: str | None = Field(description="the calibration active in the first row")
    started_utc: str | None = Field(description="the first row's time, ISO 8601 UTC")
    started_monotonic_s: float | None = Field(description="the first row's time on the service host's monotonic clock, s")
    first_cycle: int | None
    rows_requested: int
    rows_written: int
    cycles_missing: int = Field(description="gaps in the cycle column (0 normally)")
    longest_row_gap_s: float | None = Field(default=None, description="the longest time between two rows, s (the "
                                            "rows' interval, 1/rate_hz, normally; a loop held up longer leaves a "
                                            "gap in t_s, not in cycle); null with fewer than two rows")
    rows_lost: int = Field(description="rows the loop could not keep for want of room (0 normally)")
    faults_during: bool = Field(description="the controller was in FAULT or ESTOP during the recording")
    ended: Literal["duration", "stopped", "shutdown", "fault", "write_failed"] = Field(
        description="duration reached, stopped (record_stop), shutdown of the service, fault (the loop died), or "
        "write_failed (the CSV could not be written: see write_error)")
    columns: list[dict[str, str]] = Field(description="each CSV column's name and unit")
    write_error: str | None = Field(default=None, description="why the CSV could not be written whole (a full disk; "
                                    "or it was removed or changed by someone else while it was written): it keeps its "
                                    "name NAME.csv.partial, if it is still there, and lacks rows")
    side_file_error: str | None = Field(default=None, description="why the side file could not be written")


class RecordStopReply(OkReply, RecordingSideFile):
    pass


class RecordStatusReply(OkReply):
    state: Literal["idle", "writing", "done"] = Field(description="idle: no recording yet; writing: under way (rows "
                                                      "so far in rows_written); done: the last one's side file follows")
    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False, frozen=True)


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


class WaveFigures(_Message):
    """A validated wave's figures, peaks over every loop cycle of its path."""

    duration: float = Field(description="the wave's duration, s: cycles over frequency_hz")
    cycles: int = Field(description="the wave's periods")
    samples: int = Field(description="loop cycles it runs")
    peak_leg_speed_mm_s: float = Field(description="the legs' peak speed, sensor mm/s (at most the legs' budget)")
    peak_leg_speed_leg: Leg = Field(description="the leg it is on")
    peak_leg_acceleration_mm_s2: float = Field(description="the legs' peak acceleration, mm/s² (reported: the "
                                               "geometry sets no limit on it)")
    peak_leg_acceleration_leg: Leg = Field(description="the leg it is on")
    peak_pose_velocity: Annotated[list[float], Field(min_length=6, max_length=6)] = Field(
        description="peak velocity per axis in the coordinates the wave runs in (frame zero: the pose relative to "
        "the zero posture; work and tool: the tool's pose in the work frame): mm/s for x, y, z; deg/s for roll, pitch, "
        "yaw")


class WaveReply(OkReply, WaveFigures):
    pass


class ValidateWaveReply(OkReply):
    valid: bool = Field(description="whether wave would accept it now")
    wave: WaveFigures | None = Field(description="the wave's figures, when valid")
    refusal: ErrorBody | None = Field(description="what wave would answer, when not valid")


REPLY_MODELS: dict[str, type[OkReply]] = {
    "status": StatusReply,
    "events": EventsReply,
    "stream_open": StreamOpenReply,
    "move": MoveReply,
    "validate_pose": ValidatePoseReply,
    "jog": JogReply,
    "wave": WaveReply,
    "validate_wave": ValidateWaveReply,
    "play": PlayReply,
    "validate_sequence": ValidateSequenceReply,
    "load_calibration": CalibrationReply,
    "rollback_calibration": CalibrationReply,
    "validate_calibration": ValidateCalibrationReply,
    "geometry": GeometryReply,
    "files": FilesReply,
    "read_file": ReadFileReply,
    "save_recording": SaveRecordingReply,
    "measure": MeasureReply,
    "record": RecordReply,
    "record_stop": RecordStopReply,
    "record_status": RecordStatusReply,
    "set_frames": FramesReply,
    "clear_frames": FramesReply,
    "frames": FramesReply,
}
"""The reply model of each command whose reply carries more than :class:`OkReply`."""
