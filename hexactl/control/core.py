"""The loop's per-cycle work: the controller in ros2_control's terms.

:meth:`ControlCore.step` is one cycle, run by the loop thread
(:mod:`hexactl.control.loop`) or directly by a test with simulated time, shaped like
ros2_control's read → update → write:

1. read: the actuators' feedback and the link's health; forward kinematics of the
   feedback → measured pose (:class:`~hexactl.control.pose_measurement.PoseMeasurement`;
   while ENABLED at ``fk_rate_hz`` and at each dwell's record, otherwise every cycle);
2. update: carry out the queued commands (at most :data:`MAX_COMMANDS_PER_CYCLE`; the
   motion's through :class:`~hexactl.control.motion_commands.MotionCommands`);
   supervise (:class:`~hexactl.control.supervisor.Supervisor`): an actuator reporting
   E-stop → ESTOP in any state; while ENABLED heartbeats, actuator faults and states,
   set-points applied, link → FAULT. ENABLED: the motion's update
   (:class:`~hexactl.control.motion.Motion`): next trajectory point → leg-lock
   projection → IK on the active geometry → calibration ramp → leg-lock hold → guard
   (stroke, velocity) (:class:`~hexactl.control.setpoint_path.SetpointPath`) → sequence
   playback (:class:`~hexactl.control.sequence_player.SequencePlayer`). DISABLED: follow
   the measured pose so that enabling starts where the platform is;
3. write: ENABLED or FAULT: send the set-points (FAULT: the held ones); ESTOP: repeat
   the E-stop; a reset's CLEAR_FAULT once due; DISABLED: nothing else;
4. publish an immutable :class:`~hexactl.control.snapshot.CoreSnapshot` (one reference swap);
5. after the cycle, the loop's :meth:`ControlCore.after_cycle`: the data recorder
   (:class:`~hexactl.control.recorder.CycleRecorder`) keeps a reference to a due cycle.

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

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.command_inbox import CommandInbox
from hexactl.control.config import ControllerConfig
from hexactl.control.hardware import (
    ActuatorCommand,
    ActuatorInterface,
    ActuatorState,
    EstopCause,
    FeedbackSnapshot,
    LinkHealth,
)
from hexactl.control.motion import Motion
from hexactl.control.motion_commands import MotionCommands
from hexactl.control.planning import ActiveGeometry, LegLock
from hexactl.control.pose_measurement import PoseMeasurement
from hexactl.control.preconditions import Refusal
from hexactl.control.recorder import CycleRecorder
from hexactl.control.results import ErrorCode
from hexactl.control.sequence_player import SequenceProgress, dwell_record
from hexactl.control.sequences import DwellRecord
from hexactl.control.snapshot import ControlState, CoreSnapshot, Event, MotionState
from hexactl.control.stream import StreamProgress
from hexactl.control.supervisor import ESTOP_FAULTS, Fault, Supervisor, other_controller_fault, released_legs
from hexactl.control.trajectory import KinematicState
from hexactl.control.wave_player import WaveProgress
from hexactl.kinematics.axes import RelativeMmRad

KEPT_EVENTS = 64
"""Recent events kept in the snapshot: the API process reads them from each report it
takes (the service's log, the ``events`` request), so a burst loses events to it only
past this many between two reports (their numbers say how many)."""
KEPT_CALIBRATIONS = 16
"""Calibrations a rollback can return to, the most recent first."""


class ControlCore:
    """One controller instance's cycle and state machine, coordinating its parts. Not
    thread-safe: only the loop thread calls :meth:`step`. Other threads read
    :attr:`snapshot` and append to :attr:`inbox`. A
    :class:`~hexactl.control.preconditions.CoreView`."""

    def __init__(self, hardware: ActuatorInterface, active: ActiveGeometry, config: ControllerConfig) -> None:
        self.hardware = hardware
        period_s = config.loop.period_s
        self._supervisor = Supervisor(config.supervision, period_s, active.geometry.limits.leg_velocity_mm_s * period_s)
        self._measurement = PoseMeasurement(max(1, round(config.loop.rate_hz / config.fk_rate_hz)),
                                            config.fk_tolerance_mm, config.fk_max_iterations)
        self._motion = Motion(config, active, period_s, self._dwell_record, self._event)
        self.recorder = CycleRecorder()
        self._commands = CommandInbox({
            cmd.Enable: self._enable, cmd.Disable: self._disable, cmd.EStop: self._estop, cmd.Reset: self._reset,
            cmd.LockLeg: self._lock_leg, cmd.UnlockLeg: self._unlock_leg, cmd.SwapGeometry: self._swap,
            cmd.StartRecording: self.recorder.start, cmd.StopRecording: self.recorder.stop,
            cmd.FramesSet: lambda command: None,
            **MotionCommands(self, self._motion, lambda: self._now_ns, self._event).handlers(),
        }, self._event)
        self.inbox = self._commands.queue
        self.state = ControlState.DISABLED
        self.active = active
        self.history: tuple[ActiveGeometry, ...] = ()  # the calibrations active before, oldest first
        self.feedback: FeedbackSnapshot | None = None
        self.link: LinkHealth | None = None
        self._cycle = 0
        self._counter = 0  # of the next set-points sent
        self._now_ns = 0
        self._faults: tuple[Fault, ...] = ()
        self._events: tuple[Event, ...] = ()
        self._estop_cause = EstopCause.OPERATOR  # of the E-stop latched last
        self.snapshot: CoreSnapshot | None = None

    # -- the CoreView attributes that are not fields -----------------------------------

    @property
    def motion(self) -> MotionState:
        return self._motion.state(self.state is ControlState.ENABLED)

    @property
    def sequence(self) -> SequenceProgress | None:
        return self._motion.player.progress

    @property
    def pose_measured(self) -> RelativeMmRad | None:
        return self._measurement.pose

    @property
    def lock(self) -> LegLock | None:
        return self._motion.lock

    @property
    def ramp_active(self) -> bool:
        return self._motion.path.ramp.active

    @property
    def wave(self) -> WaveProgress | None:
        return self._motion.wave.progress

    @property
    def stream(self) -> StreamProgress | None:
        return self._motion.stream.progress

    # -- the cycle ---------------------------------------------------------------------

    def step(self, now_ns: int) -> None:
        """Run one cycle at monotonic time ``now_ns``: read, update, write, publish."""
        self._now_ns = now_ns
        self._cycle += 1
        self._update(self._read())
        self._write()
        self._publish()

    def after_cycle(self, lateness_ns: int, compute_ns: int) -> None:
        """The loop's report on the cycle just run (its lateness and compute time, ns):
        for the data recorder (:mod:`~hexactl.control.recorder`)."""
        self.recorder.capture(self.snapshot, lateness_ns, compute_ns)

    def _read(self) -> FeedbackSnapshot:
        hardware = self.hardware
        self.feedback = feedback = hardware.read_feedback()
        self.link = hardware.link_health()
        if self.state is not ControlState.ENABLED or self._measurement.due(self._cycle):
            self._measurement.measure(self._cycle, feedback, self.active, self._motion.path.pose_command)
        return feedback

    def _update(self, feedback: FeedbackSnapshot) -> None:
        now_ns = self._now_ns
        self._commands.run(now_ns)
        supervisor = self._supervisor
        if self.state is not ControlState.ESTOP and supervisor.estop_reported(feedback, now_ns):
            self._enter_estop("an actuator reports E-stop (hardware chain)", cause=EstopCause.SAFETY_CHAIN)
        if self.state is ControlState.ENABLED:
            if faults := supervisor.faults(feedback, self.link, self._counter - 1, now_ns):
                self._enter_fault(tuple(faults))
            elif fault := self._motion.update(self.active, now_ns):
                self._enter_fault((fault,))
        elif self.state is ControlState.FAULT and (fault := other_controller_fault(self.link)):
            self._enter_fault((fault,))  # FAULT holds: it sends set-points too
        elif self.state is ControlState.DISABLED and self._measurement.pose is not None:
            self._motion.follow(self._measurement.pose, feedback.positions_mm)

    def _write(self) -> None:
        hardware = self.hardware
        now_ns = self._now_ns
        supervisor = self._supervisor
        if self.state in (ControlState.ENABLED, ControlState.FAULT):  # FAULT: hold (module docstring)
            setpoints = self._motion.path.setpoints
            supervisor.sent(self._counter, setpoints, hardware.send_setpoints(self._counter, setpoints))
            self._counter += 1
        elif self.state is ControlState.ESTOP and supervisor.estop_due(now_ns):
            self._send_estop()
        if supervisor.clear_fault_due(self.feedback, now_ns):
            hardware.send_command(None, ActuatorCommand.CLEAR_FAULT)

    def _dwell_record(self, sequence: str, waypoint: int) -> DwellRecord:
        """The record at the end of waypoint ``waypoint``'s dwell, with this cycle's measured pose."""
        feedback, measurement, path = self.feedback, self._measurement, self._motion.path
        if feedback is not None and measurement.cycle != self._cycle:
            measurement.measure(self._cycle, feedback, self.active, path.pose_command)
        return dwell_record(sequence, waypoint, self._now_ns, path.pose_command, measurement.pose, path.setpoints,
                            feedback)

    # -- state changes -----------------------------------------------------------------

    def _enter_fault(self, faults: tuple[Fault, ...]) -> None:
        """Latch FAULT for ``faults`` (beside those latched, in FAULT already); release the
        leg of those a hold would strain (:func:`~hexactl.control.supervisor.released_legs`);
        E-stop for those holding cannot hold (:data:`~hexactl.control.supervisor.ESTOP_FAULTS`)."""
        self.state = ControlState.FAULT
        self._faults += faults
        self._motion.freeze("fault", f"a fault latched: {', '.join(fault.code for fault in faults)}")
        for fault in faults:
            self._event(fault.code, fault.message)
        for leg in released_legs(faults):
            self.hardware.send_command(leg, ActuatorCommand.DISABLE)
        if stopping := [fault.code for fault in faults if fault.code in ESTOP_FAULTS]:
            self._enter_estop(f"{', '.join(stopping)}: holding cannot stop actuators that another "
                              "controller drives too", cause=EstopCause.CONTROLLER_FAULT)

    def _send_estop(self) -> None:
        if self.hardware.send_estop(self._estop_cause):
            self._supervisor.estop_sent(self._now_ns)
        else:
            self._supervisor.estop_failed()

    def _enter_estop(self, reason: str, sender: str | None = None, cause: EstopCause = EstopCause.OPERATOR) -> None:
        """Latch ESTOP for ``reason``; its fault names ``sender`` (who sent the E-stop), as the
        event does; its frames, sent now and repeated while it lasts, carry ``cause``."""
        self._estop_cause = cause
        self._send_estop()
        self._supervisor.latched_estop()
        self.state = ControlState.ESTOP
        self._faults = self._faults + (Fault("estop", f"{reason} from {sender}" if sender else reason),)
        self._motion.freeze("fault", f"an E-stop latched: {reason}")
        self._event("estop", reason)

    def _to_disabled(self) -> None:
        """DISABLE sent: every actuator brakes; the motion and any leg lock end."""
        self.state = ControlState.DISABLED
        self._motion.lock = None
        self._motion.freeze("aborted", "the controller was disabled")

    # -- commands ------------------------------------------------------------------------

    def _enable(self, command: cmd.Enable) -> Refusal:
        if self.state is ControlState.ENABLED:  # raced another enable: the state asked for, as the facade says
            return None
        if refusal := preconditions.check_enable(self, self._supervisor.heartbeat_timeout_s):
            return refusal
        assert self.feedback is not None and self.pose_measured is not None
        if not self.hardware.send_command(None, ActuatorCommand.ENABLE):
            self.hardware.send_command(None, ActuatorCommand.DISABLE)  # undo the legs that did get it
            return ErrorCode.SEND_FAILED, (
                f"the link could not send ENABLE to every actuator ({self.hardware.link_health().detail or 'no detail'}); "
                "nothing was enabled: try again once all six report"
            )
        self._motion.start(self.pose_measured, self.feedback.positions_mm)
        self._supervisor.enabled(self._now_ns)
        self._faults = ()
        self.state = ControlState.ENABLED
        return None

    def _disable(self, command: cmd.Disable) -> Refusal:
        if self.state is ControlState.DISABLED:  # raced another disable: the state asked for, as the facade says
            return None
        if refusal := preconditions.check_disable(self):
            return refusal
        self.hardware.send_command(None, ActuatorCommand.DISABLE)
        self._to_disabled()
        return None

    def _estop(self, command: cmd.EStop) -> Refusal:
        if self.state is not ControlState.ESTOP:
            self._enter_estop("estop command", command.sender)
        return None

    def _reset(self, command: cmd.Reset) -> Refusal:
        if refusal := preconditions.check_reset(self):
            return refusal
        self.hardware.send_command(None, ActuatorCommand.DISABLE)
        self._supervisor.reset(self._now_ns)
        self._faults = ()
        self._to_disabled()
        return None

    def _lock_leg(self, command: cmd.LockLeg) -> Refusal:
        if refusal := preconditions.check_lock(self):
            return refusal
        self._motion.lock_leg(command.leg)
        self._supervisor.expect(command.leg, ActuatorState.LOCKED, self._now_ns)
        self.hardware.send_command(command.leg, ActuatorCommand.LOCK)
        return None

    def _unlock_leg(self, command: cmd.UnlockLeg) -> Refusal:
        if refusal := preconditions.check_unlock(self):
            return refusal
        assert self.lock is not None
        leg = self.lock.leg
        self.hardware.send_command(leg, ActuatorCommand.UNLOCK)
        self._supervisor.expect(leg, ActuatorState.ENABLED, self._now_ns)
        self._motion.unlock_leg()
        return None

    def _swap(self, command: cmd.SwapGeometry) -> Refusal:
        new, stale = command.active, self._motion.stale(command.epoch)
        if refusal := preconditions.check_swap(self, new) or stale or preconditions.check_rollback(self.history, command):
            return refusal
        old, self.active = self.active, new
        self._motion.swap(new, self.state is ControlState.ENABLED)
        self.history = self.history[:-1] if command.rollback else (self.history + (old,))[-KEPT_CALIBRATIONS:]
        self._measurement.geometry_changed()
        self._event("calibration_swapped", f"calibration {old.calibration_id} → {new.calibration_id}"
                    f"{' (rollback)' if command.rollback else ''} from {new.source}")
        return None

    # -- publishing ----------------------------------------------------------------------

    def _event(self, code: str, message: str) -> None:
        seq = self._events[-1].seq + 1 if self._events else 1
        self._events = (self._events + (Event(seq, self._now_ns, code, message, self._commands.sender),))[-KEPT_EVENTS:]

    def _publish(self) -> None:
        motion = self._motion
        trajectory, path = motion.trajectory, motion.path
        # Disabled, a plan starts where enabling starts the generator: at rest on the commanded
        # pose, which follows the platform; not where the last motion left the generator.
        disabled = self.state is ControlState.DISABLED
        self.snapshot = CoreSnapshot(
            t_ns=self._now_ns, cycle=self._cycle, state=self.state, motion=self.motion, epoch=motion.epoch,
            pose_command=path.pose_command, trajectory=KinematicState.at_rest(path.pose_command) if disabled else
            trajectory.state(), goal=None if disabled else trajectory.goal,
            frames=None if disabled else trajectory.frames, pose_measured=self._measurement.pose, setpoints=path.setpoints,
            feedback=self.feedback, link=self.link, lock=motion.lock, active=self.active,
            previous=self.history[-1] if self.history else None, ramp_active=path.ramp.active,
            sequence=motion.player.progress, last_sequence=motion.player.report, faults=self._faults,
            events=self._events, outcomes=self._commands.outcomes, clamped_cycles=path.clamped_cycles,
            clamped_legs=path.clamped_legs, fk_failures=self._measurement.failures, motion_end_ns=motion.end_ns,
            recorder=self.recorder.state, jog=motion.jogger.progress, last_jog=motion.jogger.report,
            wave=motion.wave.progress, stream=motion.stream.progress, last_stream=motion.stream.report,
        )
