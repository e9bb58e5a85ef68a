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

from collections.abc import Sequence
from typing import Any

from hexactl.control.calibration_swaps import CalibrationSwaps
from hexactl.control.config import ControllerConfig
from hexactl.control.frame_commands import FrameCommands
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.jog_commands import JogCommands
from hexactl.control.move_commands import MoveCommands
from hexactl.control.recording_commands import RecordingCommands
from hexactl.control.recorder import Row
from hexactl.control.sequence_player import SequenceReport
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.host import LoopHost
from hexactl.control.planning import ActiveGeometry, PlanningContext
from hexactl.control.results import CommandResult
from hexactl.control.state_commands import StateCommands
from hexactl.control.stream_commands import StreamCommands, TargetResult
from hexactl.control.sequence_commands import SequenceCommands
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.sequences import MotionSequence
from hexactl.control.telemetry import PERCENTILES_MAX_AGE_S, EventLog, Telemetry, events_after, status_result, telemetry_of
from hexactl.control.validated_under import ValidatedUnder
from hexactl.control.wave_commands import WaveCommands
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.soft_limits import NO_SOFT_LIMITS


class Controller:
    """The facade of the control core: one method per command, over a
    :class:`~hexactl.control.host.LoopHost` (a loop in another process; for the loop in a
    thread of this process, which it also starts, steps and stops:
    :class:`~hexactl.control.local_controller.LocalController`).

    ``nominal``: the platform's design geometry. Its ``[limits]`` are the actuators' and
    platform's: a calibration is refused unless its own equal them, so no calibration
    file can widen what is enforced, and unless each of its parameters lies within the
    plausibility bounds of the nominal one (:mod:`hexactl.kinematics.plausibility`).
    ``ticket_start``: the first ticket number; facades sharing one loop take disjoint
    ranges (outcomes are found by ticket).
    """

    def __init__(self, host: LoopHost, *, config: ControllerConfig, nominal: Geometry,
                 ticket_start: int = 1, frames: OperatorFrames | None = None) -> None:
        self.config = config
        self.nominal = nominal
        self._host = host
        self._commands = CommandSubmitter(host, config, ticket_start)
        self.frames = FrameCommands(frames or OperatorFrames(), lambda: self.snapshot, self._commands)
        self._jogs = JogCommands(lambda: self.snapshot, self._context, self._commands, config.jog_deadman_s)
        self.recordings = RecordingCommands(self._commands, lambda: self.snapshot)
        self._waves = WaveCommands(lambda: self.snapshot, self._context, self._commands)
        self._streams = StreamCommands(lambda: self.snapshot, self._context, self._commands, host.submit,
                                       config.stream, config.loop.rate_hz)
        self._moves = MoveCommands(lambda: self.snapshot, lambda: self.frames.current, self._context, self._commands)
        self._sequences = SequenceCommands(lambda: self.snapshot, self._context, self._commands)
        self._calibrations = CalibrationSwaps(lambda: self.snapshot, self._commands, config, nominal)
        self._states = StateCommands(host, lambda: self.snapshot, self._commands, config.supervision)

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

    def events(self, after: int = 0, now_ns: int | None = None) -> EventLog:
        """The loop's kept events (faults, refusals, commands, sequence and calibration
        changes) numbered after ``after``, oldest first, read at ``now_ns`` on the loop's
        clock (default: the snapshot's time, which lags the loop by up to a report: a
        client placing the events on its own clock from it placed them that much late)."""
        snapshot = self.snapshot
        return events_after(snapshot.events, snapshot.t_ns if now_ns is None else now_ns, after)

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
        return self._states.enable(deadline_ns)

    def disable(self) -> CommandResult:
        """Disable the actuators (at rest only: stop first); a leg lock ends, and the reply says so."""
        return self._states.disable()

    def stop(self) -> CommandResult:
        """Brake smoothly to rest where the motion happens to end; aborts a sequence.
        Never refused: at rest, or disabled, it says there was nothing to stop."""
        return self._states.stop()

    def estop(self) -> CommandResult:
        """Emergency stop, latched until reset. Sent from this thread at once where the
        actuators are reachable from here, and by the loop, which latches and repeats it."""
        return self._states.estop()

    def reset(self) -> CommandResult:
        """Clear a latched FAULT or ESTOP: DISABLE and CLEAR_FAULT to all, state DISABLED; a
        leg lock ends, and the reply says so. The reply waits, for the loop's grace after a
        reset at most, until no actuator reports FAULT or ESTOP (they leave E-stop once they
        have seen none for a moment), so that an enable right after it is not refused for
        that; one that still does is named."""
        return self._states.reset()

    def validate_pose(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
                      frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
                      validated_under: ValidatedUnder | None = None) -> CommandResult:
        """Would :meth:`move` accept this? Plans and checks the whole path, moves nothing;
        with the predicted accuracy at the tool point on arrival (``details.predicted_accuracy``,
        None without a calibration covariance) and what it was validated under
        (``details.validated_under``, a :class:`~hexactl.control.validated_under.ValidatedUnder`
        to send back with the move)."""
        return self._moves.validate(pose, duration, speed, frame, relative, tolerance_mm, validated_under)

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
        return self._moves.move(pose, duration, speed, frame, relative, tolerance_mm, validated_under, deadline_ns)

    def predicted_accuracy(self) -> dict[str, Any] | None:
        """The predicted 1σ error at the tool point for the commanded pose now
        (:mod:`~hexactl.control.accuracy`); None without a calibration covariance."""
        return self._moves.accuracy_now()

    def jog(self, velocity: Sequence[float], frame: Frame = Frame.ZERO, *, renews: int | None = None,
            restarts: int | None = None, deadline_ns: int | None = None) -> CommandResult:
        """Jog at ``velocity`` (mm/s for x, y, z; deg/s for roll, pitch, yaw) in ``frame``
        while renewed: send it again at least every ``jog_deadman_s`` or the platform brakes
        to rest. The same velocity and frame renew the jog under way, another re-plans it,
        all zeros release it (brake to rest). It heads for the first limit ahead, soft or
        hard, and comes to rest on it (``details.end``; :mod:`~hexactl.control.jog_planning`).
        ``renews``: the number of the jog this renews; refused ``jog_ended`` (with
        ``details.reason``) once that jog has ended, stopped by anyone, lapsed or replaced,
        instead of starting a new one. ``restarts``: the number of a jog whose deadman
        lapsed (its renewal was refused with ``details.lapsed``): a new jog in its place,
        refused ``jog_ended`` if anything came after the lapse (a stop from anyone)."""
        return self._jogs.jog(velocity, frame, deadline_ns, renews, restarts)

    def leg_lock(self, leg: int, *, deadline_ns: int | None = None) -> CommandResult:
        """Brake leg ``leg`` (1–6) at its current length; later moves keep it there."""
        return self._states.leg_lock(leg, deadline_ns)

    def leg_unlock(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Release the locked leg; the pose being held becomes the target (no step)."""
        return self._states.leg_unlock(deadline_ns)

    def validate_sequence(self, sequence: MotionSequence | str) -> CommandResult:
        """Would :meth:`play` accept this sequence (or built-in name) from here? Plans and
        checks every waypoint's path from where the move under way ends, at rest (a play needs
        rest; disabled, from where the platform is), moves nothing; the same details as :meth:`play`'s, in leg-lock mode with how
        far each waypoint is moved onto the locked leg's constraint
        (``details.lock_corrections_mm``). It does not ask for ENABLED: checked while
        disabled, a path error shows before enabling."""
        return self._sequences.validate(sequence)

    def play(self, sequence: MotionSequence | str, *, deadline_ns: int | None = None) -> CommandResult:
        """Play a sequence, or a built-in one by name; every waypoint's path is validated
        before the first moves. In leg-lock mode each waypoint is projected onto the locked
        leg's constraint, and ``details.lock_corrections_mm`` says how far."""
        return self._sequences.play(sequence, deadline_ns)

    def pause(self) -> CommandResult:
        """Pause the sequence: brake to rest mid-move, or freeze the dwell's clock."""
        return self._sequences.pause()

    def resume(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Continue a paused sequence; the rest of an interrupted move is planned and
        validated from where it stopped, at the segment's cruise speed."""
        return self._sequences.resume(deadline_ns)

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
        return self._sequences.abort()

    def load_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Validate a calibrated geometry and swap it in at a cycle boundary, ramping the
        set-points to it; refused with the reason otherwise (the active one stays)."""
        return self._calibrations.load(geometry, calibration_id, source)

    def validate_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Would :meth:`load_calibration` accept it now? The same checks, nothing swapped;
        success details ``calibration_id`` and ``change_mm`` (the largest set-point change
        the swap would make at the current pose)."""
        return self._calibrations.validate(geometry, calibration_id, source)

    def active_geometry(self) -> ActiveGeometry:
        """The geometry the loop runs now (calibrated or nominal), with its identity."""
        return self.snapshot.active

    def rollback_calibration(self) -> CommandResult:
        """Swap back to the calibration active before the last load (validated and ramped
        like a load); again, to the one before that, and so on (the last
        :data:`~hexactl.control.core.KEPT_CALIBRATIONS`)."""
        return self._calibrations.rollback()

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
