"""The loop's per-cycle work: the controller in ros2_control's terms.

:meth:`ControlCore.step` is one cycle, run by the loop thread
(:mod:`hexactl.control.loop`) or directly by a test with simulated time:

1. read the actuators' feedback and the link's health;
2. forward kinematics of the feedback → measured pose (warm-started; while ENABLED at
   ``fk_rate_hz`` and at each dwell's record, otherwise every cycle);
3. carry out the queued commands (at most :data:`MAX_COMMANDS_PER_CYCLE`);
4. supervise (ENABLED only): heartbeats, actuator faults and states, set-points
   applied, link → FAULT; an actuator reporting E-stop → ESTOP in any state;
5. ENABLED: next trajectory point → leg-lock projection (warm-started from the previous
   cycle's, a few iterations at most, as planning checked) → IK on the active geometry →
   calibration ramp → leg-lock hold → guard (stroke, velocity) → send;
   FAULT: send the held set-points; ESTOP: repeat the E-stop; DISABLED: send nothing,
   and follow the measured pose so that enabling starts where the platform is;
6. publish an immutable :class:`CoreSnapshot` (one reference swap).

States. DISABLED → ``enable`` → ENABLED (holding or moving). FAULT is latched until
``reset``; ESTOP likewise. ``reset`` sends DISABLE and CLEAR_FAULT to all actuators and
returns to DISABLED.

Hold in FAULT: the loop keeps sending the last set-points it sent, with fresh counters,
to every actuator. The healthy actuators hold their lengths actively and in agreement,
so the platform stays where it was whatever has failed; stopping the stream instead
would leave each actuator to its own watchdog, at different moments and possibly
unpowered under load. Nothing is disabled until the operator resets.

Every cycle does a bounded amount of work: no planning, no validation, no I/O besides
the hardware interface's non-blocking calls.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import StrEnum
from math import ceil, isnan

from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.guard import guard_setpoints
from hexactl.control.hardware import (
    ACTUATOR_COUNT,
    LINK_FAILED_STATES,
    ActuatorCommand,
    ActuatorInterface,
    ActuatorState,
    FeedbackSnapshot,
    LinkHealth,
)
from hexactl.control.planning import ActiveGeometry, LegLock, Segment, track_locked
from hexactl.control.results import ErrorCode
from hexactl.control.sequences import DwellRecord
from hexactl.control.trajectory import PoseTrajectory, StepResult
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg

MAX_COMMANDS_PER_CYCLE = 8
"""Commands carried out per cycle at most; the rest wait for the next cycle."""

KEPT_EVENTS = 64
"""Recent events and command outcomes kept in the snapshot."""


class ControlState(StrEnum):
    DISABLED = "disabled"
    ENABLED = "enabled"
    FAULT = "fault"
    ESTOP = "estop"


class MotionState(StrEnum):
    HOLDING = "holding"  # at rest on the target (also whenever not ENABLED)
    MOVING = "moving"
    STOPPING = "stopping"  # braking to rest after stop, pause or abort


class SequencePhase(StrEnum):
    MOVING = "moving"
    DWELLING = "dwelling"
    PAUSING = "pausing"  # braking after pause, mid-move
    PAUSED = "paused"


@dataclass(frozen=True, slots=True)
class Fault:
    """Why the loop latched FAULT or ESTOP; ``leg`` 1–6 when one actuator is the cause."""

    code: str
    message: str
    leg: int | None = None


@dataclass(frozen=True, slots=True)
class Event:
    """Something the loop did or refused, for the log; ``t_ns`` monotonic."""

    t_ns: int
    code: str
    message: str


@dataclass(frozen=True, slots=True)
class SequenceProgress:
    """The playing sequence: ``waypoint`` 1-based (the one being approached or dwelt
    at) of ``segments``; ``paused_in_move``: a pause interrupted the move."""

    name: str
    waypoint: int
    phase: SequencePhase
    segments: tuple[Segment, ...]
    paused_in_move: bool

    @property
    def total(self) -> int:
        return len(self.segments)

    @property
    def segment(self) -> Segment:
        return self.segments[self.waypoint - 1]

    @property
    def remaining(self) -> tuple[Segment, ...]:
        """The segments after the current one."""
        return self.segments[self.waypoint:]


@dataclass(frozen=True, slots=True)
class SequenceReport:
    """The current or the last sequence: ``status`` playing, finished, aborted or fault."""

    name: str
    status: str
    records: tuple[DwellRecord, ...]


@dataclass(frozen=True, slots=True)
class CoreSnapshot:
    """What the loop looked like at the end of cycle ``cycle`` (``t_ns`` monotonic).

    Poses relative to the zero posture in mm and rad; ``trajectory`` the generator's
    (position, velocity, acceleration), which a new plan starts from, and ``goal`` its
    target (None while braking); set-points and
    feedback sensor mm. ``clamped_cycles``: cycles in which the guard changed a
    set-point (each one means a plan was wrong); ``clamped_legs``: bit mask of the
    legs it ever changed.
    """

    t_ns: int
    cycle: int
    state: ControlState
    motion: MotionState
    epoch: int
    pose_command: tuple[float, ...]
    trajectory: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    goal: tuple[float, ...] | None
    pose_measured: tuple[float, ...] | None
    setpoints: tuple[float, ...]
    feedback: FeedbackSnapshot | None
    link: LinkHealth | None
    lock: LegLock | None
    active: ActiveGeometry
    previous: ActiveGeometry | None
    ramp_active: bool
    sequence: SequenceProgress | None
    last_sequence: SequenceReport | None
    faults: tuple[Fault, ...]
    events: tuple[Event, ...]
    outcomes: tuple[cmd.Outcome, ...]
    clamped_cycles: int
    clamped_legs: int
    fk_failures: int


# -- preconditions ------------------------------------------------------------------------
# Pure functions of a "view": the live ControlCore or a CoreSnapshot (same attribute
# names). The controller checks them in the caller's thread for an immediate answer;
# the loop checks them again when it carries the command out (the state may have moved).

Refusal = tuple[ErrorCode, str] | None  # (code, message) or None when allowed


def _enabled(view) -> Refusal:
    if view.state is ControlState.ENABLED:
        return None
    if view.state in (ControlState.FAULT, ControlState.ESTOP):
        return ErrorCode.LATCHED, f"{view.state.value} is latched: reset first"
    return ErrorCode.NOT_ENABLED, "the controller is disabled: enable first"


def _at_rest(view) -> Refusal:
    if view.sequence is not None:
        return ErrorCode.BUSY, f"sequence {view.sequence.name!r} is playing: abort it first"
    if view.motion is not MotionState.HOLDING:
        return ErrorCode.BUSY, "the platform is moving: stop first"
    return None


def check_enable(view, heartbeat_timeout_s: float) -> Refusal:
    if view.state is ControlState.ENABLED:
        return ErrorCode.ALREADY_ENABLED, "already enabled"
    if view.state is not ControlState.DISABLED:
        return ErrorCode.LATCHED, f"{view.state.value} is latched: reset first"
    if view.feedback is None:
        return ErrorCode.HEARTBEAT_MISSING, "no feedback from the actuators yet"
    low, high = view.active.stroke
    for leg, actuator in enumerate(view.feedback.actuators, start=1):
        if not actuator.heartbeat_age_s <= heartbeat_timeout_s:
            return ErrorCode.HEARTBEAT_MISSING, f"leg {leg}: no report for {actuator.heartbeat_age_s:.3f} s"
        if actuator.state in (ActuatorState.FAULT, ActuatorState.ESTOP) or actuator.fault_bits:
            return ErrorCode.ACTUATOR_FAULT, f"leg {leg}: {actuator.state.name}, fault bits 0x{actuator.fault_bits:x}"
        if isnan(actuator.position_mm):
            return ErrorCode.HEARTBEAT_MISSING, f"leg {leg}: no position reported yet"
        if not low <= actuator.position_mm <= high:
            return ErrorCode.OUTSIDE_STROKE, f"leg {leg} at {actuator.position_mm:.3f} mm, outside the stroke [{low:g}, {high:g}] mm"
    if view.pose_measured is None:
        return ErrorCode.POSE_UNKNOWN, "forward kinematics of the feedback failed: the platform's pose is unknown"
    return None


def check_disable(view) -> Refusal:
    return _enabled(view) or _at_rest(view)


def check_move(view) -> Refusal:
    if refusal := _enabled(view):
        return refusal
    if view.sequence is not None:
        return ErrorCode.BUSY, f"sequence {view.sequence.name!r} is playing: abort it first"
    return None


def check_lock(view) -> Refusal:
    if refusal := _enabled(view) or _at_rest(view):
        return refusal
    if view.lock is not None:
        return ErrorCode.LEG_LOCKED, f"leg {view.lock.leg} is already locked"
    if view.ramp_active:
        return ErrorCode.BUSY, "a calibration change is still ramping in"
    return None


def check_unlock(view) -> Refusal:
    if refusal := _enabled(view):
        return refusal
    if view.lock is None:
        return ErrorCode.NOT_LOCKED, "no leg is locked"
    return _at_rest(view)


def check_play(view) -> Refusal:
    return _enabled(view) or _at_rest(view)


def check_pause(view) -> Refusal:
    if view.sequence is None:
        return ErrorCode.NO_SEQUENCE, "no sequence is playing"
    if view.sequence.phase in (SequencePhase.PAUSING, SequencePhase.PAUSED):
        return ErrorCode.ALREADY_PAUSED, "the sequence is already paused"
    return None


def check_resume(view) -> Refusal:
    if view.sequence is None:
        return ErrorCode.NO_SEQUENCE, "no sequence is playing"
    if view.sequence.phase is not SequencePhase.PAUSED:
        return ErrorCode.NOT_PAUSED, f"the sequence is {view.sequence.phase.value}, not paused"
    return None


def check_abort(view) -> Refusal:
    return None if view.sequence is not None else (ErrorCode.NO_SEQUENCE, "no sequence is playing")


def check_reset(view) -> Refusal:
    if view.state is ControlState.ENABLED:
        return ErrorCode.NOT_LATCHED, "nothing to reset: the controller is enabled (disable or estop)"
    return None


def check_swap(view, new: ActiveGeometry) -> Refusal:
    # The new geometry's limits equal the hardware's (Controller.load_calibration), so
    # the set-points already respect its stroke.
    if view.lock is not None:
        return ErrorCode.LEG_LOCKED, f"leg {view.lock.leg} is locked: unlock before changing the calibration"
    return None


# -- the core -------------------------------------------------------------------------------


@dataclass(slots=True)
class _Run:
    """The playing sequence, owned by the loop."""

    name: str
    segments: tuple[Segment, ...]
    index: int
    phase: SequencePhase
    dwell_end_ns: int = 0
    dwell_left_ns: int = 0
    paused_in_move: bool = False


class ControlCore:
    """One controller instance's cycle logic and state; not thread-safe: only the loop
    thread calls :meth:`step`. Other threads read :attr:`snapshot` and append to
    :attr:`inbox`."""

    def __init__(self, hardware: ActuatorInterface, active: ActiveGeometry, config: ControllerConfig) -> None:
        self.hardware = hardware
        self.config = config
        self.inbox: deque[cmd.Command] = deque()
        self.period_s = config.loop.period_s
        supervision = config.supervision
        self._heartbeat_timeout_s = supervision.heartbeat_timeout_s
        self._state_timeout_ns = round(supervision.state_timeout_s * 1e9)
        self._lag_limit = ceil(supervision.setpoint_lag_s / self.period_s)
        self._estop_repeat_ns = round(supervision.estop_repeat_s * 1e9)
        self._estop_clear_holdoff_ns = round(supervision.estop_clear_holdoff_s * 1e9)
        self._trajectory = PoseTrajectory(config.motion, self.period_s)
        self._handlers = {
            cmd.Enable: self._enable, cmd.Disable: self._disable, cmd.Stop: self._stop, cmd.EStop: self._estop,
            cmd.Reset: self._reset, cmd.Move: self._move, cmd.LockLeg: self._lock_leg, cmd.UnlockLeg: self._unlock_leg,
            cmd.Play: self._play, cmd.Pause: self._pause, cmd.Resume: self._resume, cmd.Abort: self._abort,
            cmd.SwapGeometry: self._swap,
        }
        self.state = ControlState.DISABLED
        self.active = active
        self.previous: ActiveGeometry | None = None
        self.lock: LegLock | None = None
        self.feedback: FeedbackSnapshot | None = None
        self.link: LinkHealth | None = None
        self.pose_command: list[float] = [0.0] * 6
        self.pose_measured: tuple[float, ...] | None = None
        self.setpoints: list[float] = [0.0] * ACTUATOR_COUNT
        self._measured_absolute: tuple[float, ...] | None = None
        self._fk_every = max(1, round(config.loop.rate_hz / config.fk_rate_hz))
        self._measured_cycle = 0  # the cycle FK last ran in
        self._max_step_mm = active.geometry.limits.leg_velocity_mm_s * self.period_s
        self._epoch = 0
        self._cycle = 0
        self._counter = 0
        self._send_failures = 0
        # Per leg: the state it should report, and until when it may still be getting there.
        self._expected = [ActuatorState.ENABLED] * ACTUATOR_COUNT
        self._settling_until_ns = [0] * ACTUATOR_COUNT
        self._estop_grace_until_ns = 0  # after a reset the actuators need time to leave ESTOP
        self._next_estop_ns = 0
        self._last_estop_ns: int | None = None  # when the loop last sent an E-stop
        self._clear_fault_due_ns: int | None = None  # a reset's CLEAR_FAULT waits for the E-stop hold-off
        self._ramp_offset: list[float] | None = None
        self._ramp_left = 0.0
        self._ramp_decrement = 0.0
        self._run: _Run | None = None
        self._last_sequence: SequenceReport | None = None
        self._faults: tuple[Fault, ...] = ()
        self._events: tuple[Event, ...] = ()
        self._outcomes: tuple[cmd.Outcome, ...] = ()
        self._clamped_cycles = 0
        self._clamped_legs = 0
        self._fk_failures = 0
        self._now_ns = 0
        self.snapshot: CoreSnapshot | None = None

    # -- view attributes shared with CoreSnapshot (for the check_* functions) ----------

    @property
    def motion(self) -> MotionState:
        if self.state is not ControlState.ENABLED or not self._trajectory.moving:
            return MotionState.HOLDING
        return MotionState.STOPPING if self._trajectory.halting else MotionState.MOVING

    @property
    def sequence(self) -> SequenceProgress | None:
        run = self._run
        if run is None:
            return None
        return SequenceProgress(run.name, run.index + 1, run.phase, run.segments, run.paused_in_move)

    @property
    def ramp_active(self) -> bool:
        return self._ramp_offset is not None

    # -- the cycle ---------------------------------------------------------------------

    def step(self, now_ns: int) -> None:
        """Run one cycle at monotonic time ``now_ns``."""
        self._now_ns = now_ns
        self._cycle += 1
        hardware = self.hardware
        self.feedback = feedback = hardware.read_feedback()
        self.link = hardware.link_health()
        if self.state is not ControlState.ENABLED or self._cycle - self._measured_cycle >= self._fk_every:
            self._measure(feedback)
        inbox = self.inbox
        for _ in range(MAX_COMMANDS_PER_CYCLE):
            if not inbox:
                break
            self._execute(inbox.popleft())
        if self.state is not ControlState.ESTOP and now_ns >= self._estop_grace_until_ns and any(
            a.state is ActuatorState.ESTOP for a in feedback.actuators
        ):
            self._enter_estop("an actuator reports E-stop (hardware chain)")
        if self.state is ControlState.ENABLED:
            self._supervise(feedback)
        if self.state is ControlState.ENABLED:
            self._advance()
        if self.state in (ControlState.ENABLED, ControlState.FAULT):
            self._send()
        elif self.state is ControlState.ESTOP:
            if now_ns >= self._next_estop_ns:
                self._send_estop()
        if self._clear_fault_due_ns is not None and now_ns >= self._clear_fault_due_ns:
            self._clear_fault_due_ns = None
            hardware.send_command(None, ActuatorCommand.CLEAR_FAULT)
        if self.state is ControlState.DISABLED and self.pose_measured is not None:
            # Start from where the platform is.
            self.pose_command = list(self.pose_measured)
            self.setpoints = list(feedback.positions_mm)
        self._publish()

    def _measure(self, feedback: FeedbackSnapshot) -> None:
        self._measured_cycle = self._cycle
        active = self.active
        lengths = [p + z for p, z in zip(feedback.positions_mm, active.geometry.zero_lengths)]
        guess = self._measured_absolute or active.absolute(self.pose_command)
        result = forward_kinematics(active.geometry.legs, lengths, guess,
                                    self.config.fk_tolerance_mm, self.config.fk_max_iterations)
        if result.ok:
            self._measured_absolute = result.pose
            self.pose_measured = tuple(a - h for a, h in zip(result.pose, active.home))
        else:
            self._measured_absolute = self.pose_measured = None
            self._fk_failures += 1

    def _supervise(self, feedback: FeedbackSnapshot) -> None:
        faults = []
        now = self._now_ns
        last_sent = self._counter - 1
        for leg, actuator in enumerate(feedback.actuators, start=1):
            expected = self._expected[leg - 1]
            if not actuator.heartbeat_age_s <= self._heartbeat_timeout_s:
                faults.append(Fault("heartbeat_lost", f"leg {leg}: no report for {actuator.heartbeat_age_s:.3f} s", leg))
            elif actuator.state is ActuatorState.FAULT or actuator.fault_bits:
                faults.append(Fault("actuator_fault", f"leg {leg} reports fault bits 0x{actuator.fault_bits:x}", leg))
            elif actuator.state is not expected:
                if now >= self._settling_until_ns[leg - 1]:
                    faults.append(Fault("actuator_state", f"leg {leg} is {actuator.state.name}, expected {expected.name}", leg))
            elif self._settling_until_ns[leg - 1]:
                self._settling_until_ns[leg - 1] = 0  # got there: from now on any deviation counts
            elif expected is ActuatorState.ENABLED and last_sent - actuator.setpoint_counter > self._lag_limit:
                faults.append(Fault("setpoints_not_applied", f"leg {leg} applied set-point {actuator.setpoint_counter}, "
                                    f"last sent {last_sent}", leg))
        link = self.link
        if link is not None and link.bus_state in LINK_FAILED_STATES:
            faults.append(Fault("link_failed", f"bus {link.bus_state.value}" + (f": {link.detail}" if link.detail else "")))
        if self._send_failures >= self.config.supervision.max_send_failures:
            faults.append(Fault("send_failed", f"{self._send_failures} set-point sends failed in a row"))
        if faults:
            self._enter_fault(tuple(faults))

    def _advance(self) -> None:
        """The ENABLED cycle: next target → set-points (not yet sent)."""
        trajectory = self._trajectory
        lock = self.lock
        previous_target = trajectory.position if lock is not None else None
        result = trajectory.update()
        if result is StepResult.ERROR:
            self._enter_fault((Fault("planner_error", "the trajectory generator refused its input"),))
            return
        active = self.active
        pose = trajectory.position
        if lock is not None:
            # pose_command: what last cycle's target (the position before this update) was projected to.
            projected = track_locked(active, lock, pose, previous_target, self.pose_command,
                                     self.config.lock_cycle_iterations)
            if not projected.ok:
                self._enter_fault((Fault("leg_lock_projection", f"leg-lock projection failed: "
                                         f"{projected.status.name.lower()} after {projected.iterations} iterations",
                                         lock.leg),))
                return
            pose = tuple(a - h for a, h in zip(projected.pose, active.home))
        desired = sensor_setpoints(active.geometry.legs, active.absolute(pose))
        offset = self._ramp_offset
        if offset is not None:
            left = self._ramp_left
            desired = [d + left * o for d, o in zip(desired, offset)]
            self._ramp_left = left - self._ramp_decrement
            if self._ramp_left <= 0.0:
                self._ramp_offset = None
        if lock is not None:
            desired[lock.leg - 1] = lock.sensor_mm  # exactly the locked value, not IK's rounding of it
        setpoints, clamped = guard_setpoints(desired, self.setpoints, active.stroke, self._max_step_mm)
        if clamped:
            if not self._clamped_cycles:
                self._event("guard_clamped", f"the set-point guard limited legs mask 0x{clamped:x}: a plan was wrong")
            self._clamped_cycles += 1
            self._clamped_legs |= clamped
        self.setpoints = setpoints
        self.pose_command = list(pose)
        if self._run is not None:
            self._sequence_step(result)

    def _send(self) -> None:
        if self.hardware.send_setpoints(self._counter, self.setpoints):
            self._send_failures = 0
        else:
            self._send_failures += 1
        self._counter += 1

    def _sequence_step(self, result: StepResult) -> None:
        run = self._run
        assert run is not None
        now = self._now_ns
        if result is StepResult.FINISHED:
            if run.phase is SequencePhase.MOVING:
                run.phase = SequencePhase.DWELLING
                run.dwell_end_ns = now + round(run.segments[run.index].dwell_s * 1e9)
        if run.phase is SequencePhase.PAUSING and not self._trajectory.moving:
            run.phase = SequencePhase.PAUSED
        if run.phase is SequencePhase.DWELLING and now >= run.dwell_end_ns:
            self._record(run)
            run.index += 1
            if run.index == len(run.segments):
                self._end_sequence("finished")
            else:
                self._start_segment(run.segments[run.index])
                run.phase = SequencePhase.MOVING

    def _record(self, run: _Run) -> None:
        feedback = self.feedback
        if feedback is not None and self._measured_cycle != self._cycle:
            self._measure(feedback)  # the dwell's record has this cycle's measured pose
        measured = self.pose_measured
        record = DwellRecord(
            run.name, run.index + 1, self._now_ns / 1e9,
            tuple(float(v) for v in pose_mm_rad_to_mm_deg(self.pose_command)),
            None if measured is None else tuple(float(v) for v in pose_mm_rad_to_mm_deg(measured)),
            tuple(self.setpoints), feedback.positions_mm if feedback else (float("nan"),) * ACTUATOR_COUNT)
        last = self._last_sequence
        records = last.records + (record,) if last is not None else (record,)
        self._last_sequence = SequenceReport(run.name, "playing", records)

    def _end_sequence(self, status: str) -> None:
        run = self._run
        if run is None:
            return
        records = self._last_sequence.records if self._last_sequence else ()
        self._last_sequence = SequenceReport(run.name, status, records)
        self._run = None
        self._event(f"sequence_{status}", f"sequence {run.name!r} {status} after {len(records)} of {len(run.segments)} waypoints")

    def _start_segment(self, segment: Segment) -> bool:
        """Head for ``segment``'s goal; False if the generator refuses it from the current
        state, which only a move replacing a running one can meet (see ``move_to``)."""
        return self._trajectory.move_to(segment.goal, segment.time_scale, segment.velocity_scale)

    # -- state changes -----------------------------------------------------------------

    def _enter_fault(self, faults: tuple[Fault, ...]) -> None:
        self.state = ControlState.FAULT
        self._faults = faults
        self._freeze("fault")
        for fault in faults:
            self._event(fault.code, fault.message)

    def _send_estop(self) -> None:
        self.hardware.send_estop()
        self._last_estop_ns = self._now_ns
        self._next_estop_ns = self._now_ns + self._estop_repeat_ns

    def _enter_estop(self, reason: str) -> None:
        self._send_estop()
        self._clear_fault_due_ns = None
        self.state = ControlState.ESTOP
        self._faults = self._faults + (Fault("estop", reason),)
        self._freeze("fault")
        self._event("estop", reason)

    def _freeze(self, sequence_status: str) -> None:
        """Forget any motion: the commanded pose and set-points stay as they are."""
        self._trajectory.reset(self.pose_command)
        self._ramp_offset = None
        self._end_sequence(sequence_status)
        self._epoch += 1

    # -- commands ------------------------------------------------------------------------

    def _execute(self, command: cmd.Command) -> None:
        deadline_ns = command.deadline_ns
        if deadline_ns is not None and self._now_ns > deadline_ns:
            refusal: Refusal = ErrorCode.EXPIRED, (
                f"its deadline passed {(self._now_ns - deadline_ns) / 1e6:.1f} ms before the loop reached it; "
                "not carried out: send it again with a longer timeout if it is still wanted")
        else:
            refusal = self._handlers[type(command)](command)
        code, message = refusal if refusal else (None, "done")
        if refusal:
            self._event("command_refused", f"{type(command).__name__}: {message}")
        self._outcomes = (self._outcomes + (cmd.Outcome(command.ticket, code, message),))[-KEPT_EVENTS:]

    def _expect(self, leg: int | None, state: ActuatorState) -> None:
        """Leg 1–6 (or all) must report ``state`` within ``state_timeout_s``."""
        for i in range(ACTUATOR_COUNT) if leg is None else (leg - 1,):
            self._expected[i] = state
            self._settling_until_ns[i] = self._now_ns + self._state_timeout_ns

    def _stale(self, epoch: int) -> Refusal:
        if epoch != self._epoch:
            return ErrorCode.STALE_PLAN, "the target changed while the command was being planned: plan again"
        return None

    def _enable(self, command: cmd.Enable) -> Refusal:
        if refusal := check_enable(self, self._heartbeat_timeout_s):
            return refusal
        assert self.feedback is not None and self.pose_measured is not None
        if not self.hardware.send_command(None, ActuatorCommand.ENABLE):
            self.hardware.send_command(None, ActuatorCommand.DISABLE)  # undo the legs that did get it
            return ErrorCode.SEND_FAILED, (
                f"the link could not send ENABLE to every actuator ({self.hardware.link_health().detail or 'no detail'}); "
                "nothing was enabled: try again once all six report"
            )
        self.setpoints = list(self.feedback.positions_mm)
        self.pose_command = list(self.pose_measured)
        self._trajectory.reset(self.pose_command)
        self._expect(None, ActuatorState.ENABLED)
        self._send_failures = 0
        self._faults = ()
        self.state = ControlState.ENABLED
        self._epoch += 1
        return None

    def _disable(self, command: cmd.Disable) -> Refusal:
        if refusal := check_disable(self):
            return refusal
        self.hardware.send_command(None, ActuatorCommand.DISABLE)
        self.state = ControlState.DISABLED
        self.lock = None
        self._freeze("aborted")
        return None

    def _stop(self, command: cmd.Stop) -> Refusal:
        self._end_sequence("aborted")
        self._trajectory.halt()
        self._epoch += 1
        return None

    def _estop(self, command: cmd.EStop) -> Refusal:
        if self.state is not ControlState.ESTOP:
            self._enter_estop("estop command")
        return None

    def _reset(self, command: cmd.Reset) -> Refusal:
        if refusal := check_reset(self):
            return refusal
        self.hardware.send_command(None, ActuatorCommand.DISABLE)
        # Actuators refuse CLEAR_FAULT while an E-stop is recent: send it once the hold-off
        # since the loop's last E-stop has passed (at once after a FAULT without E-stops).
        due = self._now_ns
        if self._last_estop_ns is not None:
            due = max(due, self._last_estop_ns + self._estop_clear_holdoff_ns)
        self._clear_fault_due_ns = due
        self.state = ControlState.DISABLED
        self.lock = None
        self._faults = ()
        self._estop_grace_until_ns = self._clear_fault_due_ns + self._state_timeout_ns
        self._freeze("aborted")
        return None

    def _move(self, command: cmd.Move) -> Refusal:
        if refusal := check_move(self) or self._stale(command.epoch):
            return refusal
        if not self._start_segment(command.segment):
            return ErrorCode.STALE_PLAN, ("the motion went on while the move was planned, and from where it is now the "
                                          "trajectory generator refuses it: plan again")
        return None

    def _lock_leg(self, command: cmd.LockLeg) -> Refusal:
        if refusal := check_lock(self):
            return refusal
        leg = command.leg
        self.lock = LegLock(leg, self.setpoints[leg - 1])
        self._expect(leg, ActuatorState.LOCKED)
        self.hardware.send_command(leg, ActuatorCommand.LOCK)
        self._epoch += 1
        return None

    def _unlock_leg(self, command: cmd.UnlockLeg) -> Refusal:
        if refusal := check_unlock(self):
            return refusal
        assert self.lock is not None
        leg = self.lock.leg
        self.hardware.send_command(leg, ActuatorCommand.UNLOCK)
        self._expect(leg, ActuatorState.ENABLED)
        self.lock = None
        # Bumpless: the projected pose being commanded becomes the generator's state.
        self._trajectory.reset(self.pose_command)
        self._epoch += 1
        return None

    def _play(self, command: cmd.Play) -> Refusal:
        if refusal := check_play(self) or self._stale(command.epoch):
            return refusal
        self._run = _Run(command.name, command.segments, 0, SequencePhase.MOVING)
        self._last_sequence = SequenceReport(command.name, "playing", ())
        self._start_segment(command.segments[0])
        self._event("sequence_started", f"sequence {command.name!r}: {len(command.segments)} waypoints")
        return None

    def _pause(self, command: cmd.Pause) -> Refusal:
        if refusal := check_pause(self):
            return refusal
        run = self._run
        assert run is not None
        if run.phase is SequencePhase.MOVING:
            self._trajectory.halt()
            run.phase = SequencePhase.PAUSING  # PAUSED once at rest (see _sequence_step)
            run.paused_in_move = True
        else:
            run.phase = SequencePhase.PAUSED
            run.paused_in_move = False
            run.dwell_left_ns = max(0, run.dwell_end_ns - self._now_ns)
        self._epoch += 1
        return None

    def _resume(self, command: cmd.Resume) -> Refusal:
        if refusal := check_resume(self) or self._stale(command.epoch):
            return refusal
        run = self._run
        assert run is not None
        if run.paused_in_move:
            if command.remainder is None:
                return ErrorCode.INVALID_ARGUMENT, "the sequence was paused mid-move: resume needs the rest of the move"
            self._start_segment(command.remainder)
            run.phase = SequencePhase.MOVING
        else:
            run.dwell_end_ns = self._now_ns + run.dwell_left_ns
            run.phase = SequencePhase.DWELLING
        self._epoch += 1
        return None

    def _abort(self, command: cmd.Abort) -> Refusal:
        if refusal := check_abort(self):
            return refusal
        return self._stop(cmd.Stop(command.ticket))

    def _swap(self, command: cmd.SwapGeometry) -> Refusal:
        new = command.active
        if refusal := check_swap(self, new) or self._stale(command.epoch):
            return refusal
        old = self.active
        if self.state is ControlState.ENABLED:
            # Ramp from the set-points being sent to the new geometry's: the difference
            # at the present pose fades out linearly, all legs together, at
            # calibration_ramp_fraction of the leg velocity limit (moves are planned
            # within the rest of it), while the commanded pose carries on.
            target = sensor_setpoints(new.geometry.legs, new.absolute(self.pose_command))
            offset = [s - t for s, t in zip(self.setpoints, target)]
            largest = max(abs(o) for o in offset)
            rate = self.config.calibration_ramp_fraction * new.geometry.limits.leg_velocity_mm_s * self.period_s
            if largest > 0.0:
                self._ramp_offset, self._ramp_left, self._ramp_decrement = offset, 1.0, rate / largest
        self.previous, self.active = old, new
        self._max_step_mm = new.geometry.limits.leg_velocity_mm_s * self.period_s
        self._measured_absolute = None  # another model: warm-start from the command
        self._measured_cycle = -self._fk_every  # and measure on it next cycle
        self._epoch += 1
        self._event("calibration_swapped", f"calibration {old.calibration_id} → {new.calibration_id}")
        return None

    # -- publishing ----------------------------------------------------------------------

    def _event(self, code: str, message: str) -> None:
        self._events = (self._events + (Event(self._now_ns, code, message),))[-KEPT_EVENTS:]

    def _publish(self) -> None:
        self.snapshot = CoreSnapshot(
            self._now_ns, self._cycle, self.state, self.motion, self._epoch, tuple(self.pose_command),
            self._trajectory.state(), self._trajectory.goal, self.pose_measured, tuple(self.setpoints), self.feedback, self.link, self.lock,
            self.active, self.previous, self.ramp_active, self.sequence, self._last_sequence, self._faults,
            self._events, self._outcomes, self._clamped_cycles, self._clamped_legs, self._fk_failures,
        )
