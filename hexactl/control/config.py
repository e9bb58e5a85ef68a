"""The controller's parameters: one validated, frozen object, read once at start-up."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

from hexactl.control.realtime import RealtimeConfig
from hexactl.control.stats import DEFAULT_WINDOW
from hexactl.control.trajectory import MotionLimits
from hexactl.kinematics.numbers import Number, WholeNumber


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class LoopConfig(_Frozen):
    """Timing of the loop thread."""

    rate_hz: Number = Field(default=500.0, ge=10.0, le=2000.0, description="cycle rate; 500 or 1000 in practice")
    spin_window_us: Number = Field(
        default=300.0, ge=0.0,
        description="the last stretch before a deadline is busy-waited instead of slept: a sleep wakes only as "
        "precisely as the timer slack allows, and the loop then holds the GIL when the deadline comes",
    )
    stats_window: WholeNumber = Field(default=DEFAULT_WINDOW, ge=1, description="cycles kept for lateness percentiles")
    realtime: RealtimeConfig = RealtimeConfig()

    @property
    def period_ns(self) -> int:
        return round(1e9 / self.rate_hz)

    @property
    def period_s(self) -> float:
        return self.period_ns / 1e9


class SupervisionConfig(_Frozen):
    """When the loop declares a FAULT (checked every cycle while ENABLED), or brakes on its own."""

    heartbeat_timeout_s: Number = Field(default=0.05, gt=0, description="an actuator silent this long is lost")
    state_timeout_s: Number = Field(
        default=0.5, gt=0, description="time an actuator has to reach a commanded state (enabled, locked …)"
    )
    setpoint_lag_s: Number = Field(
        default=0.05, gt=0, description="set-points the actuators have not applied for this long mean a broken link"
    )
    following_error_mm: Number = Field(
        default=15.0, gt=0,
        description="an enabled actuator farther than this from the set-point it reports applied, for "
        "following_error_s, is jammed, overloaded or slipping (the firmware's own limit is a last resort). "
        "Above what a healthy drive lags at full speed: the protocol's actuators (400 mm/s, 10 m/s²) brake "
        "toward their target, so they trail it by v²/2a, 8 mm at 400 mm/s",
    )
    following_error_s: Number = Field(
        default=0.1, ge=0, description="how long the following error may exceed following_error_mm before FAULT"
    )
    locked_slip_mm: Number = Field(
        default=0.2, gt=0,
        description="a locked leg farther than this from where it was locked, for following_error_s, has slipped on "
        "its brake or is overloaded. Below the step an actuator takes from where it measures after UNLOCK (its speed "
        "limit × the loop period: 0.4 mm at 400 mm/s and 1000 Hz; the smaller of the two applies), so that unlocking "
        "never asks a jump of it",
    )
    command_silence_s: Number = Field(
        default=1.0, gt=0,
        description="nothing from the API (no command, no heartbeat) for this long, and the loop brakes a motion "
        "under way to rest: a frozen API process could not pass on an E-stop. Ten times the API's longest "
        "heartbeat interval (0.1 s), so that a host under load does not stop a motion",
    )
    max_send_failures: WholeNumber = Field(default=3, ge=1, description="consecutive failed set-point sends before FAULT")
    estop_repeat_s: Number = Field(default=0.1, gt=0, description="while ESTOP is latched, the E-stop is re-sent this often")
    estop_clear_holdoff_s: Number = Field(
        default=0.3, ge=0,
        description="actuators refuse to clear an E-stop until they have seen none for a while (firmware_proto: "
        "250 ms); reset sends CLEAR_FAULT this long after the last E-stop the loop sent",
    )


class ControllerConfig(_Frozen):
    """Everything the controller needs besides the hardware and the geometry."""

    loop: LoopConfig = LoopConfig()
    motion: MotionLimits = MotionLimits()
    stream: MotionLimits = Field(
        default=MotionLimits(max_velocity=(600.0, 600.0, 400.0, 30.0, 30.0, 40.0),
                             max_acceleration=(2000.0, 2000.0, 1500.0, 100.0, 100.0, 150.0),
                             max_jerk=(50000.0, 50000.0, 40000.0, 2500.0, 2500.0, 4000.0)),
        description="limits of a pose stream's tracking (hexactl.control.stream), with the velocities, acceleration "
                    "and jerk a simulator's cues need (with the motion's jerk a stream would lag by a quarter of a "
                    "second). The velocities are caps per axis: what limits a stream is its legs' speed, the box "
                    "shaped per target so that none exceeds it (hexactl.control.stream_commands.stream_velocity_limits)")
    supervision: SupervisionConfig = SupervisionConfig()
    calibration_ramp_fraction: Number = Field(
        default=0.1, gt=0, lt=1,
        description="share of leg_velocity_mm_s a calibration swap ramps at; moves are planned within the rest",
    )
    calibration_max_change_mm: Number = Field(
        default=25.0, gt=0, description="a calibration that moves a set-point more than this at the current pose is refused"
    )
    lock_max_correction_mm: Number = Field(
        default=25.0, gt=0, description="leg-lock: a goal farther than this from the locked-leg constraint is refused"
    )
    lock_cycle_iterations: WholeNumber = Field(default=3, ge=1, description="leg-lock: projection iterations per cycle")
    path_step_mm: Number = Field(default=2.0, gt=0, description="move validation: sample spacing in translation")
    path_step_deg: Number = Field(default=0.1, gt=0, description="move validation: sample spacing in rotation")
    fk_rate_hz: Number = Field(
        default=100.0, gt=0,
        description="while ENABLED, forward kinematics of the feedback (the measured pose) runs at about this rate "
        "(every round(loop rate / this) cycles) and at every dwell it records; in the other states, every cycle. "
        "It is the costliest step of a cycle (BENCHMARKS.md, Kinematics) and feeds telemetry and records only",
    )
    fk_tolerance_mm: Number = Field(default=1e-6, gt=0, description="forward kinematics of the feedback: tolerance")
    fk_max_iterations: WholeNumber = Field(default=10, ge=1, description="forward kinematics of the feedback: iteration cap")
    command_timeout_s: Number = Field(default=0.5, gt=0, description="how long a caller waits for the loop's verdict")
    jog_deadman_s: Number = Field(
        default=0.2, ge=0.02, le=5.0,
        description="a jog goes on for this long after each renewal (its client sends jog again at least this "
        "often), then brakes to rest",
    )

    @model_validator(mode="after")
    def _timeouts_span_cycles(self) -> ControllerConfig:
        period = self.loop.period_s
        for name in ("heartbeat_timeout_s", "setpoint_lag_s"):
            if getattr(self.supervision, name) < 3 * period:
                raise ValueError(f"supervision.{name} must span at least three loop periods ({3 * period:g} s)")
        if self.jog_deadman_s < 3 * period:
            raise ValueError(f"jog_deadman_s must span at least three loop periods ({3 * period:g} s)")
        return self
