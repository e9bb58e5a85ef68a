"""What the controller answers: a result per command, with a snake_case error code."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

REPORT_SILENT_S = 1.0
"""s: a loop whose latest report is older than this
(:attr:`~hexactl.control.stats.LoopStats.report_age_s`) has stopped reporting, its process
stopped or hung (a running loop reports every 10 ms at most): displays say so rather than
show its last state as current, and commands other than a stop are not sent to it
(:attr:`ErrorCode.LOOP_SILENT`). Standard library only here: the CLI reads it."""

OTHER_CONTROLLER_WINDOW_S = 1.0
"""s: another controller heard on the bus this recently
(:attr:`~hexactl.control.hardware.LinkHealth.other_controller_age_s`) refuses ``enable``
(:attr:`ErrorCode.OTHER_CONTROLLER`) and, while enabled, latches FAULT. A controller that
runs is heard every few ms (it sends SYNC every loop cycle, in every state): a second is
long against that, keeps a tool's lone command from passing unnoticed, and once the other
is stopped the operator waits no longer than that. Standard library only here: the CLI
reads it."""



class ErrorCode(StrEnum):
    """Why a command was refused. The API sends the value as is."""

    INVALID_ARGUMENT = "invalid_argument"  # the request itself is malformed (NaN, wrong leg, …)
    NOT_ENABLED = "not_enabled"  # needs ENABLED; the controller is DISABLED
    LATCHED = "latched"  # FAULT or ESTOP is latched: reset first
    NOT_LATCHED = "not_latched"  # reset while ENABLED
    BUSY = "busy"  # moving, a sequence playing, or a calibration ramping in
    PATH_VIOLATION = "path_violation"  # the move's path leaves the workspace: see details.violations
    PLANNING_FAILED = "planning_failed"  # the trajectory generator refused the move
    LOCK_UNREACHABLE = "lock_unreachable"  # leg-lock: no pose near the goal keeps the locked length
    LEG_LOCKED = "leg_locked"  # not allowed while a leg is locked (or one is already)
    NOT_LOCKED = "not_locked"
    HEARTBEAT_MISSING = "heartbeat_missing"  # enable: an actuator is silent
    ACTUATOR_FAULT = "actuator_fault"  # enable: an actuator reports a fault
    OUTSIDE_STROKE = "outside_stroke"  # an actuator (or set-point) is outside the stroke
    POSE_UNKNOWN = "pose_unknown"  # forward kinematics of the feedback failed
    NO_SEQUENCE = "no_sequence"
    UNKNOWN_SEQUENCE = "unknown_sequence"  # play: not a built-in sequence (details.built_in lists them)
    ALREADY_PAUSED = "already_paused"
    NOT_PAUSED = "not_paused"
    STALE_PLAN = "stale_plan"  # the target changed between planning and execution: try again
    INVALID_GEOMETRY = "invalid_geometry"  # the calibration fails validation: see details
    CALIBRATION_CHANGE_TOO_LARGE = "calibration_change_too_large"
    NO_PREVIOUS_CALIBRATION = "no_previous_calibration"
    OUTSIDE_SOFT_LIMITS = "outside_soft_limits"  # set_frames: the platform would be outside the new soft limits
    SEND_FAILED = "send_failed"  # the link refused a frame (E-stop, ENABLE)
    LOOP_FAILED = "loop_failed"  # the loop thread died: see status
    LOOP_TIMEOUT = "loop_timeout"  # the loop gave no verdict in time (the command may still run)
    LOOP_SILENT = "loop_silent"  # the loop has not reported for REPORT_SILENT_S: not sent (a stop: queued)
    NOT_RECORDING = "not_recording"  # record_stop with no recording under way
    NO_STREAM = "no_stream"  # stream_close with no stream open
    JOG_ENDED = "jog_ended"  # a jog renewal for a jog that is no longer under way: send jog again
    EXPIRED = "expired"  # the command's deadline had passed when the loop reached it: not carried out
    ACCURACY_INSUFFICIENT = "accuracy_insufficient"  # the predicted error at the tool point exceeds the move's tolerance
    CHANGED_SINCE_VALIDATION = "changed_since_validation"  # a move's frames, calibration or goal changed since it was validated
    OTHER_CONTROLLER = "other_controller"  # enable: another controller drives the same actuators (its frames heard)


@dataclass(frozen=True, slots=True)
class CommandResult:
    """``ok`` True when accepted (``error`` None); otherwise ``error`` says why.
    ``details``: JSON-friendly extras (violations, the projected goal, a ticket …)."""

    ok: bool
    error: ErrorCode | None
    message: str
    details: Mapping[str, object] = field(default_factory=dict)

    @classmethod
    def success(cls, message: str, **details: object) -> CommandResult:
        return cls(True, None, message, details)

    @classmethod
    def failure(cls, error: ErrorCode | str, message: str, **details: object) -> CommandResult:
        return cls(False, ErrorCode(error), message, details)


DEADMAN_LAPSED = "the deadman lapsed (no renewal in time)"
JOG_RELEASED = "released"


_WAVE_ENDED_AS = {"finished": "finished", "aborted": "was aborted (stop or abort)",
                  "fault": "ended on a fault, an E-stop or a disable"}


def wave_ended_message(phase: str, cycle: int, cycles: int) -> str:
    """How a wave ended, by its phase (``finished``, ``aborted``, ``fault``), in its period
    ``cycle`` of ``cycles``: the loop's event and ``hexactl wave --wait`` say it alike ("the
    wave ended aborted" read as a slip, found from outside)."""
    return f"the wave {_WAVE_ENDED_AS.get(phase, f'ended {phase}')} in its cycle {cycle} of {cycles}"


JOG_RESTART_ADVICE = ("it is not renewed; send jog without renews to start a new one (a held button: release it "
                      "and press again)")
"""What a client of the API does about a jog that has ended; the command line says its own."""


def jog_ended_message(jog: int, reason: str | None) -> str:
    """Why a renewal of ``jog``, which brakes or has ended (``reason``, if known), is refused.
    Without a reason the loop knows nothing of it: it ended before the last jog, or the
    number names no jog (a client's mistake, which "has ended" would hide)."""
    state = (f"has ended ({reason})" if reason
             else "is not under way (it ended before the last jog, or no jog has that number)")
    return f"jog {jog} {state}: {JOG_RESTART_ADVICE}"
