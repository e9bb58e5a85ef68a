"""The controller facade: one method per command the API exposes, plus telemetry.

Threading. Methods are called from any thread (the API's, a CLI's, a test's). Each does
its heavy work there — argument checks, planning, path validation, calibration dry runs
— against the loop's latest :class:`~hexactl.control.core.CoreSnapshot`, then hands an
immutable command (:mod:`hexactl.control.commands`) to the loop's host
(:mod:`hexactl.control.host`): a deque in this process, or a pipe to the loop's process
when the facade serves the API in a process of its own. With the loop running by
itself, the method then waits (at most ``command_timeout_s``) for the
loop's verdict, because the state may have changed meanwhile and the loop checks again;
when the loop is stepped by hand (tests, simulation) it returns at once with
``details["pending"] = True`` and the verdict is read later with :meth:`Controller.outcome`.

No method raises for bad input: every one returns a
:class:`~hexactl.control.results.CommandResult`. Poses in and out are relative to the
zero posture, mm and degrees; leg set-points and feedback are actuator sensor mm.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.accuracy import predicted_accuracy, tolerance_refusal
from hexactl.control.calibration_checks import acceptance_refusal, swap_refusal
from hexactl.control.config import ControllerConfig
from hexactl.control.frame_commands import FrameCommands
from hexactl.control.frames import Frame, OperatorFrames, convert, requested_goal
from hexactl.control.jog_commands import JogCommands
from hexactl.control.recording_commands import RecordingCommands
from hexactl.control.recorder import Row
from hexactl.control.sequence_player import SequenceReport
from hexactl.control.snapshot import ControlState, CoreSnapshot, Event, MotionState
from hexactl.control.host import LoopHost
from hexactl.control.planning import (
    ActiveGeometry,
    Plan,
    PlanningContext,
    Refusal,
    Waypoint,
    plan_path,
)
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.stream_commands import StreamCommands, TargetResult
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.sequences import BUILTIN_SEQUENCES, MotionSequence, UnknownSequence, builtin_sequence
from hexactl.control.telemetry import PERCENTILES_MAX_AGE_S, Telemetry, status_result, telemetry_of
from hexactl.control.validated_under import ValidatedUnder, changed_since_validation
from hexactl.control.wave_commands import WaveCommands
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.axes import validate_pose_values
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.soft_limits import NO_SOFT_LIMITS


class Controller:
    """The facade of the control core: one method per command, over a
    :class:`~hexactl.control.host.LoopHost` (a loop in another process; for the loop in a
    thread of this process, which it also starts, steps and stops:
    :class:`~hexactl.control.local_controller.LocalController`).

    ``nominal``: the platform's design geometry. Its ``[limits]`` are the actuators' and
    platform's (:attr:`hardware_limits`): a calibration is refused unless its own equal
    them, so no calibration file can widen what is enforced, and unless each of its
    parameters lies within the plausibility bounds of the nominal one
    (:mod:`hexactl.kinematics.plausibility`). ``ticket_start``: the first ticket number;
    facades sharing one loop take disjoint ranges (outcomes are found by ticket).
    """

    def __init__(self, host: LoopHost, *, config: ControllerConfig, nominal: Geometry,
                 ticket_start: int = 1, frames: OperatorFrames | None = None) -> None:
        self.config = config
        self.frames = FrameCommands(frames or OperatorFrames(), lambda: self.snapshot)
        self.nominal = nominal
        self.hardware_limits = nominal.limits
        self._host = host
        self._commands = CommandSubmitter(host, config, ticket_start)
        self._jogs = JogCommands(lambda: self.snapshot, self._context, self._commands, config.jog_deadman_s)
        self.recordings = RecordingCommands(self._commands, lambda: self.snapshot)
        self._waves = WaveCommands(lambda: self.snapshot, self._context, self._commands)
        self._streams = StreamCommands(lambda: self.snapshot, self._context, self._commands, host.submit,
                                       config.stream)

    @property
    def snapshot(self) -> CoreSnapshot:
        return self._host.snapshot

    # -- queries --------------------------------------------------------------------------

    def status(self) -> CommandResult:
        """State, calibration, sequence, faults, recent events and the loop's health."""
        return status_result(self._host.report(PERCENTILES_MAX_AGE_S), self.frames.current)

    def telemetry(self) -> Telemetry:
        """The latest cycle. The loop's lateness and compute percentiles are at most
        ``PERCENTILES_MAX_AGE_S`` old; counters and maxima are current."""
        return telemetry_of(self._host.report(PERCENTILES_MAX_AGE_S), self.frames.current)

    def events(self) -> tuple[Event, ...]:
        """The loop's recent events (faults, refusals, sequence and calibration changes)."""
        return self.snapshot.events

    def sequence_records(self) -> SequenceReport | None:
        """The playing or last played sequence's dwell records."""
        return self.snapshot.last_sequence

    def outcome(self, ticket: int) -> CommandResult | None:
        """The loop's verdict on command ``ticket`` (None if not carried out yet, or
        too long ago to be remembered)."""
        return self._commands.outcome(ticket)

    # -- commands -------------------------------------------------------------------------

    def enable(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Energise the actuators and hold the pose they are at."""
        s = self.snapshot
        if refusal := preconditions.check_enable(s, self.config.supervision.heartbeat_timeout_s):
            return CommandResult.failure(*refusal)
        return self._commands.submit(cmd.Enable, "enabled", deadline_ns=deadline_ns)

    def disable(self) -> CommandResult:
        """Disable the actuators (at rest only: stop first); a leg lock ends, and the reply says so."""
        return self._checked(preconditions.check_disable, cmd.Disable, "disabled" + self._lock_released())

    def stop(self) -> CommandResult:
        """Brake smoothly to rest where the motion happens to end; aborts a sequence.
        Never refused: at rest, or disabled, it says there was nothing to stop."""
        s = self.snapshot
        if s.state is not ControlState.ENABLED:
            message = f"nothing to stop: the controller is {s.state.value}"
        elif s.motion is MotionState.HOLDING and s.sequence is None:
            message = "nothing to stop: the platform is at rest"
        else:
            message = "stopping"
        return self._commands.submit(cmd.Stop, message)

    def estop(self) -> CommandResult:
        """Emergency stop, latched until reset. Sent from this thread at once where the
        actuators are reachable from here, and by the loop, which latches and repeats it."""
        sent = self._host.estop_now()
        result = self._commands.submit(cmd.EStop, "E-stop latched")
        if sent is False:
            return CommandResult.failure(ErrorCode.SEND_FAILED, "the E-stop frame could not be sent; the loop "
                                         "latched ESTOP and keeps repeating it", **result.details)
        return result

    def reset(self) -> CommandResult:
        """Clear a latched FAULT or ESTOP: DISABLE and CLEAR_FAULT to all, state DISABLED; a
        leg lock ends, and the reply says so."""
        return self._checked(preconditions.check_reset, cmd.Reset, "reset to disabled" + self._lock_released())

    def _lock_released(self) -> str:
        """What disabling says of the leg lock it ends: the next enable drives all six legs."""
        lock = self.snapshot.lock
        return f"; leg {lock.leg} is no longer locked: the next enable drives all six legs" if lock is not None else ""

    def validate_pose(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
                      frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
                      validated_under: ValidatedUnder | None = None) -> CommandResult:
        """Would :meth:`move` accept this? Plans and checks the whole path, moves nothing;
        with the predicted accuracy at the tool point on arrival (``details.predicted_accuracy``,
        None without a calibration covariance) and what it was validated under
        (``details.validated_under``, a :class:`~hexactl.control.validated_under.ValidatedUnder`
        to send back with the move)."""
        s, frames = self.snapshot, self.frames.current
        in_force = ValidatedUnder(calibration_id=s.active.calibration_id, frames=frames)
        if refusal := changed_since_validation(validated_under, in_force):
            return refusal
        plan = self._plan_move(s, frames, pose, duration, speed, frame, relative)
        if not plan.ok:
            return _plan_result(plan, "valid", s.active.home)
        accuracy = self._accuracy_at_goal(s, frames, plan)
        if refusal := tolerance_refusal(tolerance_mm, accuracy):
            return refusal
        result = _plan_result(plan, "valid", s.active.home)
        return CommandResult.success(result.message, **result.details, predicted_accuracy=accuracy,
                                     validated_under=in_force)

    def move(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
             frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
             validated_under: ValidatedUnder | None = None, *, deadline_ns: int | None = None) -> CommandResult:
        """Move to ``pose`` (mm/deg) in ``frame`` (:class:`~hexactl.control.frames.Frame`),
        or by it from where the motion is headed with ``relative``; validated whole first,
        soft limits too; ``duration`` s (at least, to one loop period) or ``speed`` (0, 1]
        of the velocity limits. In leg-lock mode the goal is projected onto the locked
        leg's constraint (see ``details.goal``). A move while moving replaces the running
        one (in the same frame: another frame needs rest). With ``tolerance_mm`` it is
        refused (``accuracy_insufficient``) if the predicted error at the tool point on
        arrival exceeds it (:mod:`~hexactl.control.accuracy`). With ``validated_under`` (what
        :meth:`validate_pose` said it validated under) it is refused
        (``changed_since_validation``) if the frames or the calibration changed since: it
        is planned in the very frames and on the very calibration it checks (a swap that
        reaches the loop before the move makes the loop refuse it as ``stale_plan``), so
        the platform goes to the goal validated or not at all."""
        s, frames = self.snapshot, self.frames.current
        if refusal := preconditions.check_move(s):
            return CommandResult.failure(*refusal)
        in_force = ValidatedUnder(calibration_id=s.active.calibration_id, frames=frames)
        if refusal := changed_since_validation(validated_under, in_force):
            return refusal
        plan = self._plan_move(s, frames, pose, duration, speed, frame, relative)
        if not plan.ok:
            return _plan_result(plan, "", s.active.home)
        accuracy = self._accuracy_at_goal(s, frames, plan) if tolerance_mm is not None else None
        if refusal := tolerance_refusal(tolerance_mm, accuracy):
            return refusal
        (segment,) = plan.segments
        return self._commands.submit(lambda t: cmd.Move(t, s.epoch, segment), "moving", deadline_ns=deadline_ns,
                            **_plan_result(plan, "", s.active.home).details)

    def predicted_accuracy(self) -> dict[str, Any] | None:
        """The predicted 1σ error at the tool point for the commanded pose now
        (:mod:`~hexactl.control.accuracy`); None without a calibration covariance."""
        s = self.snapshot
        return predicted_accuracy(s.active, self.frames.current.tool[:3], s.pose_command)

    def _accuracy_at_goal(self, s: CoreSnapshot, frames: OperatorFrames, plan: Plan) -> dict[str, Any] | None:
        last = plan.segments[-1]
        return predicted_accuracy(s.active, frames.tool[:3], convert(last.goal, last.frames, None, s.active.home))

    def jog(self, velocity: Sequence[float], frame: Frame = Frame.ZERO, *,
            deadline_ns: int | None = None) -> CommandResult:
        """Jog at ``velocity`` (mm/s for x, y, z; deg/s for roll, pitch, yaw) in ``frame``
        while renewed: send it again at least every ``jog_deadman_s`` or the platform brakes
        to rest. The same velocity and frame renew the jog under way, another re-plans it,
        all zeros release it (brake to rest). It heads for the first limit ahead, soft or
        hard, and comes to rest on it (``details.end``; :mod:`~hexactl.control.jog_planning`)."""
        return self._jogs.jog(velocity, frame, deadline_ns)

    def leg_lock(self, leg: int, *, deadline_ns: int | None = None) -> CommandResult:
        """Brake leg ``leg`` (1–6) at its current length; later moves keep it there."""
        if isinstance(leg, bool) or not isinstance(leg, (int, np.integer)) or not 1 <= leg <= 6:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"leg is a number from 1 to 6, got {leg!r}")
        return self._checked(preconditions.check_lock, lambda t: cmd.LockLeg(t, int(leg)), f"leg {leg} locked", deadline_ns)

    def leg_unlock(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Release the locked leg; the pose being held becomes the target (no step)."""
        return self._checked(preconditions.check_unlock, cmd.UnlockLeg, "unlocked", deadline_ns)

    def validate_sequence(self, sequence: MotionSequence | str) -> CommandResult:
        """Would :meth:`play` accept this sequence (or built-in name) from here? Plans and
        checks every waypoint's path, moves nothing."""
        resolved = _resolve_sequence(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self.snapshot
        return _plan_result(plan_path(self._context(s), s.trajectory, resolved.planning_waypoints(), s.frames), "valid",
                            s.active.home)

    def play(self, sequence: MotionSequence | str, *, deadline_ns: int | None = None) -> CommandResult:
        """Play a sequence, or a built-in one by name; every waypoint's path is validated
        before the first moves."""
        resolved = _resolve_sequence(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self.snapshot
        if refusal := preconditions.check_play(s):
            return CommandResult.failure(*refusal)
        plan = plan_path(self._context(s), s.trajectory, resolved.planning_waypoints(), s.frames)
        if not plan.ok:
            return _plan_result(plan, "", s.active.home)
        name = resolved.name
        return self._commands.submit(lambda t: cmd.Play(t, s.epoch, name, plan.segments), f"playing {name}",
                            deadline_ns=deadline_ns, **_plan_result(plan, "", s.active.home).details)

    def pause(self) -> CommandResult:
        """Pause the sequence: brake to rest mid-move, or freeze the dwell's clock."""
        return self._checked(preconditions.check_pause, cmd.Pause, "pausing")

    def resume(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Continue a paused sequence; the rest of an interrupted move is planned and
        validated from where it stopped, at the segment's cruise speed."""
        s = self.snapshot
        if refusal := preconditions.check_resume(s):
            return CommandResult.failure(*refusal)
        progress = s.sequence
        assert progress is not None
        remainder = None
        if progress.paused_in_move:
            segment = progress.segment
            waypoint = Waypoint(segment.goal.in_degrees(), None, segment.velocity_scale / segment.time_scale)
            context = self._context(s)  # the remainder runs in the frames the segment was planned in
            plan = plan_path(replace(context, frames=segment.frames or context.frames), s.trajectory, [waypoint], s.frames)
            if not plan.ok:
                return _plan_result(plan, "", s.active.home)
            (remainder,) = plan.segments
        return self._commands.submit(lambda t: cmd.Resume(t, s.epoch, remainder), "resumed", deadline_ns=deadline_ns)

    def validate_wave(self, spec: WaveSpec) -> CommandResult:
        """Would :meth:`wave` accept this? Plans and checks the whole path, moves nothing."""
        return self._waves.validate(spec)

    def wave(self, spec: WaveSpec, *, deadline_ns: int | None = None) -> CommandResult:
        """Play the wave ``spec`` from rest, its whole path validated first
        (:mod:`~hexactl.control.wave_planning`); refused, never slowed down, if too fast.
        Success details: ``duration_s``, the peak leg speed and acceleration, the peak pose
        velocity. ``stop`` or ``abort`` brake it to rest; it cannot be paused."""
        return self._waves.play(spec, deadline_ns)

    def stream_open(self, source: str, frame: Frame | str = Frame.ZERO, timeout_s: float = 0.1, *,
                    deadline_ns: int | None = None) -> CommandResult:
        """Open a pose stream from ``source`` (a name for people) of target poses in
        ``frame`` (zero or work), ended if no target comes for ``timeout_s``: the loop
        follows each target jerk-limited, a target out of reach replaced by the nearest
        reachable pose on the way to it (:mod:`~hexactl.control.stream_commands`).
        ``details.stream``: its number."""
        return self._streams.open(source, frame, timeout_s, deadline_ns)

    def stream_close(self) -> CommandResult:
        """End the pose stream: brake to rest."""
        return self._streams.close()

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None = None) -> TargetResult:
        """The open stream's next target (finite; its frame, mm and deg), numbered
        ``sequence`` and sent at ``sent_s`` (s, the sender's clock) by its sender, which
        arrived at monotonic ``received_ns``; ``before``: the sample the sender sent just
        before it (pose, sent_s), when that was not handed here. Not waited for: the loop
        takes the newest each cycle."""
        return self._streams.target(pose, sequence, sent_s, received_ns, before)

    def abort(self) -> CommandResult:
        """End the sequence or the wave and brake to rest; a sequence's records are kept."""
        return self._checked(preconditions.check_abort, cmd.Abort, "aborted")

    def load_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Validate a calibrated geometry and swap it in at a cycle boundary, ramping the
        set-points to it; refused with the reason otherwise (the active one stays)."""
        if not isinstance(geometry, Geometry):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "load_calibration takes a validated Geometry")
        if not isinstance(calibration_id, str) or not calibration_id:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "the calibration needs a non-empty id")
        new = ActiveGeometry.of(geometry, calibration_id, source)
        if refusal := acceptance_refusal(geometry, f"calibration {calibration_id}", self.nominal):
            return refusal
        if calibration_id == self.snapshot.active.calibration_id:  # nothing to swap, nor to roll back to later
            return CommandResult.success(f"calibration {calibration_id} is already active: nothing changed",
                                         calibration_id=calibration_id, change_mm=0.0)
        return self._swap(new, f"calibration {calibration_id} loaded")

    def validate_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Would :meth:`load_calibration` accept it now? The same checks, nothing swapped;
        success details ``calibration_id`` and ``change_mm`` (the largest set-point change
        the swap would make at the current pose)."""
        if not isinstance(geometry, Geometry):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "validate_calibration takes a validated Geometry")
        if refusal := acceptance_refusal(geometry, f"calibration {calibration_id}", self.nominal):
            return refusal
        checked = self._swap_check(ActiveGeometry.of(geometry, calibration_id, source))
        if isinstance(checked, CommandResult):
            return checked
        return CommandResult.success(f"calibration {calibration_id} would change the set-points by at most "
                                     f"{checked:.3f} mm", calibration_id=calibration_id, change_mm=checked)

    def active_geometry(self) -> ActiveGeometry:
        """The geometry the loop runs now (calibrated or nominal), with its identity."""
        return self.snapshot.active

    def rollback_calibration(self) -> CommandResult:
        """Swap back to the calibration active before the last load (validated and ramped
        like a load); again, to the one before that, and so on (the last
        :data:`~hexactl.control.core.KEPT_CALIBRATIONS`)."""
        s = self.snapshot
        if s.previous is None:
            return CommandResult.failure(ErrorCode.NO_PREVIOUS_CALIBRATION, "there is no earlier calibration to roll "
                                         f"back to ({s.active.calibration_id} is the first since start-up)")
        return self._swap(s.previous, f"rolled back from calibration {s.active.calibration_id} to "
                          f"{s.previous.calibration_id}", rollback=True)

    def set_frames(self, frames: OperatorFrames) -> CommandResult:
        """Make ``frames`` the operator's work and tool frames and soft limits (see
        :meth:`~hexactl.control.frame_commands.FrameCommands.set`)."""
        return self.frames.set(frames)

    def operator_frames(self) -> OperatorFrames:
        return self.frames.current

    def record(self, recording: int, name: str, divisor: int, rows: int, on_motion: bool = False) -> CommandResult:
        """Start the loop's data recorder (see :meth:`~hexactl.control.recording_commands.RecordingCommands.start`)."""
        return self.recordings.start(recording, name, divisor, rows, on_motion)

    def record_stop(self) -> CommandResult:
        """End the recording under way early."""
        return self.recordings.stop()

    def take_recorded(self) -> list[Row]:
        """The recorder's rows not taken yet, oldest first (one taker: the recording's writer)."""
        return self._host.take_recorded()

    # -- helpers ----------------------------------------------------------------------------

    def _context(self, s: CoreSnapshot, frames: OperatorFrames | None = None) -> PlanningContext:
        """What a plan from ``s`` is checked with, in ``frames`` (None: those in force now)."""
        config, frames = self.config, self.frames.current if frames is None else frames
        budget = s.active.geometry.limits.leg_velocity_mm_s * (1.0 - config.calibration_ramp_fraction)
        return PlanningContext(s.active, config.motion, config.loop.period_s, budget, s.lock,
                               config.lock_max_correction_mm, config.path_step_mm, config.path_step_deg,
                               config.lock_cycle_iterations, frames.frames(s.active.home),
                               None if frames.soft_limits == NO_SOFT_LIMITS else frames.soft_limits)

    def _plan_move(self, s: CoreSnapshot, frames: OperatorFrames, pose: Sequence[float], duration: float | None,
                   speed: float | None, frame: Frame, relative: bool) -> Plan:
        context = self._context(s, frames)
        if problem := validate_pose_values(pose) or (None if frame in tuple(Frame) else f"unknown frame {frame!r}"):
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, problem))
        target = s.goal if s.goal is not None else s.trajectory.position
        goal = requested_goal(pose, Frame(frame), bool(relative), target, s.frames, context.frames, s.active.home)
        if isinstance(goal, str):
            return Plan(refusal=Refusal(ErrorCode.INVALID_ARGUMENT, goal))
        return plan_path(context, s.trajectory, [Waypoint(goal, duration, speed)], s.frames)

    def _swap(self, new: ActiveGeometry, message: str, *, rollback: bool = False) -> CommandResult:
        """Check ``new`` (:func:`~hexactl.control.calibration_checks.swap_refusal`), then
        hand it over (with ``rollback``: the last of the history, which the loop drops)."""
        s = self.snapshot
        checked = self._swap_check(new)
        if isinstance(checked, CommandResult):
            return checked
        replaced = {"rolled_back_from": s.active.calibration_id} if rollback else {}
        return self._commands.submit(lambda t: cmd.SwapGeometry(t, s.epoch, new, rollback), message,
                                     calibration_id=new.calibration_id, change_mm=checked, **replaced)

    def _swap_check(self, new: ActiveGeometry) -> float | CommandResult:
        """The largest set-point change swapping in ``new`` makes now, mm, or the refusal."""
        s = self.snapshot
        if refusal := preconditions.check_swap(s, new):
            return CommandResult.failure(*refusal)
        return swap_refusal(s, new, self.config)

    def _checked(self, check, factory: Callable[[int], cmd.Command], message: str,
                 deadline_ns: int | None = None) -> CommandResult:
        if refusal := check(self.snapshot):
            return CommandResult.failure(*refusal)
        return self._commands.submit(factory, message, deadline_ns=deadline_ns)


def _resolve_sequence(sequence: object) -> MotionSequence | CommandResult:
    """A sequence, a built-in one by name, or the refusal."""
    if isinstance(sequence, str):
        try:
            return builtin_sequence(sequence)
        except UnknownSequence as error:
            return CommandResult.failure(ErrorCode.UNKNOWN_SEQUENCE, str(error), built_in=list(BUILTIN_SEQUENCES))
    if not isinstance(sequence, MotionSequence):
        return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "a sequence is a MotionSequence or a built-in name")
    return sequence


def _plan_result(plan: Plan, message: str, home_mm_rad: Sequence[float]) -> CommandResult:
    """The result of ``plan``: its refusal, or ``goal`` relative to the zero posture
    ``home_mm_rad`` (and ``tool_goal``, the tool's pose in the work frame, for a motion in
    it; mm and deg), ``duration_s`` and ``waypoints``."""
    if plan.refusal is not None:
        refusal = plan.refusal
        return CommandResult.failure(refusal.code, refusal.message, violations=[asdict(v) for v in refusal.violations],
                                     **refusal.details)
    last = plan.segments[-1]
    in_work = {"tool_goal": list(last.goal.in_degrees())} if last.frames is not None else {}
    return CommandResult.success(
        message,
        goal=list(convert(last.goal, last.frames, None, home_mm_rad).in_degrees()),
        duration_s=sum(seg.duration_s + seg.dwell_s for seg in plan.segments),
        waypoints=len(plan.segments),
        **in_work,
    )
