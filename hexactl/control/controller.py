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

import itertools
import time
from math import isfinite
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.core import (
    ControlState,
    CoreSnapshot,
    Event,
    Fault,
    SequenceReport,
    check_abort,
    check_disable,
    check_enable,
    check_lock,
    check_move,
    check_pause,
    check_play,
    check_reset,
    check_resume,
    check_swap,
    check_unlock,
)
from hexactl.control.hardware import ActuatorInterface
from hexactl.control.host import LoopHost, LoopThread
from hexactl.control.planning import (
    ActiveGeometry,
    Plan,
    PlanningContext,
    Waypoint,
    assess_path,
    piecewise_line,
    plan_path,
)
from hexactl.control.realtime import RealtimeReport
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.sequences import BUILTIN_SEQUENCES, MotionSequence, builtin_sequence
from hexactl.control.stats import LoopStats
from hexactl.kinematics.geometry import Geometry, limits_differences
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.plausibility import implausibilities
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg
from hexactl.kinematics.workspace import assess_readings


TELEMETRY_PERCENTILES_MAX_AGE_S = 0.25
"""Telemetry recomputes the loop's percentiles (a sort of its window) at most this often."""

RAMP_SAMPLES = 11
"""A calibration change is checked at this many fractions of its set-point ramp (0, 0.1 … 1)."""


@dataclass(frozen=True, slots=True)
class SequenceTelemetry:
    """The playing sequence: ``index`` 1-based waypoint being approached or dwelt at."""

    name: str
    index: int
    total: int
    phase: str


@dataclass(frozen=True, slots=True)
class Telemetry:
    """One cycle's picture. ``t``: monotonic time of the cycle, s. Poses relative to the
    zero posture, mm and deg (``pose_measured`` None when the feedback has no FK
    solution). Legs in sensor mm; an actuator not heard from yet reads NaN in
    ``leg_feedback`` (and, while DISABLED, in ``leg_setpoints``, which then mirror the
    feedback); ``leg_feedback`` is None before the first read."""

    t: float
    state: str
    motion: str
    pose_command: tuple[float, ...]
    pose_measured: tuple[float, ...] | None
    leg_setpoints: tuple[float, ...]
    leg_feedback: tuple[float, ...] | None
    locked_leg: int | None
    calibration_id: str
    sequence: SequenceTelemetry | None
    faults: tuple[Fault, ...]
    loop: LoopStats
    realtime: RealtimeReport | None = None  # what the loop thread's real-time set-up obtained


class Controller:
    """The facade of the control core: one method per command, over a
    :class:`~hexactl.control.host.LoopHost` (the loop in a thread of this process,
    :meth:`in_thread`, or in another process).

    ``nominal``: the platform's design geometry. Its ``[limits]`` are the actuators' and
    platform's (:attr:`hardware_limits`): a calibration is refused unless its own equal
    them, so no calibration file can widen what is enforced, and unless each of its
    parameters lies within the plausibility bounds of the nominal one
    (:mod:`hexactl.kinematics.plausibility`). ``ticket_start``: the first ticket number;
    facades sharing one loop take disjoint ranges (outcomes are found by ticket).
    """

    def __init__(self, host: LoopHost, *, config: ControllerConfig, nominal: Geometry,
                 ticket_start: int = 1) -> None:
        self.config = config
        self.nominal = nominal
        self.hardware_limits = nominal.limits
        self._host = host
        self._thread = host if isinstance(host, LoopThread) else None
        self._tickets = itertools.count(ticket_start)  # next() on a count is atomic in CPython

    @classmethod
    def in_thread(
        cls,
        hardware: ActuatorInterface,
        geometry: Geometry,
        calibration_id: str,
        *,
        calibration_source: str = "",
        config: ControllerConfig | None = None,
        nominal: Geometry | None = None,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> Controller:
        """The controller with its loop in this process, driving ``hardware``, on
        ``geometry`` (with its identity: the caller computes the id, e.g. a content hash).
        ``nominal`` defaults to ``geometry``. ``clock_ns``: monotonic time for
        cycles stepped by hand and for the first one, run here, so status and telemetry
        work at once and the commanded pose starts where the platform is.

        :raises ValueError: if ``geometry``'s limits differ from ``nominal``'s, or it is
            not a plausible calibration of it (the message names each parameter and bound)
        """
        nominal = nominal or geometry
        if differences := limits_differences(geometry.limits, nominal.limits):
            raise ValueError(f"the geometry's [limits] differ from the hardware's: {'; '.join(differences)}")
        if problems := implausibilities(geometry, nominal):
            raise ValueError(_implausible_message("the start calibration", problems))
        config = config or ControllerConfig()
        thread = LoopThread(hardware, ActiveGeometry.of(geometry, calibration_id, calibration_source), config, clock_ns)
        return cls(thread, config=config, nominal=nominal)

    # -- lifecycle (the loop in this process) ---------------------------------------------

    @property
    def thread(self) -> LoopThread:
        """The loop of this process.

        :raises RuntimeError: if the loop runs in another process
        """
        if self._thread is None:
            raise RuntimeError("the control loop runs in another process")
        return self._thread

    @property
    def hardware(self) -> ActuatorInterface:
        """The actuators the loop of this process drives (see :attr:`thread`)."""
        return self.thread.hardware

    def start(self) -> RealtimeReport:
        """Start the loop thread; returns what the real-time set-up obtained."""
        # Plan one small move, and discard it, before the thread freezes the heap: the
        # first plan creates lazily initialised module state (numpy, ruckig, pydantic)
        # that would otherwise fill the loop's first young collection (0.5 ms, measured).
        s = self.snapshot
        plan_path(self._context(s), ((0.0,) * 6,) * 3, [Waypoint((1.0, 0.0, 0.0, 0.0, 0.0, 0.0))])
        return self.thread.loop.start()

    def shutdown(self) -> None:
        """Stop the loop thread (the actuators keep their state: disable first)."""
        self.thread.loop.stop()

    def step(self, now_ns: int) -> None:
        """Run one cycle at monotonic ``now_ns`` (tests, simulation); not while the thread runs."""
        loop = self.thread.loop
        if loop.running:
            raise RuntimeError("the loop thread is running: it steps by itself")
        loop.step(now_ns)

    @property
    def snapshot(self) -> CoreSnapshot:
        return self._host.snapshot

    # -- queries --------------------------------------------------------------------------

    def status(self) -> CommandResult:
        """State, calibration, sequence, faults, recent events and the loop's health."""
        report = self._host.report(TELEMETRY_PERCENTILES_MAX_AGE_S)
        s = report.snapshot
        return CommandResult.success(
            s.state.value,
            state=s.state.value,
            motion=s.motion.value,
            locked_leg=s.lock.leg if s.lock else None,
            calibration_id=s.active.calibration_id,
            calibration_source=s.active.source,
            previous_calibration_id=s.previous.calibration_id if s.previous else None,
            calibration_ramping=s.ramp_active,
            sequence=asdict(_sequence_telemetry(s)) if s.sequence else None,
            last_sequence={"name": s.last_sequence.name, "status": s.last_sequence.status,
                           "records": len(s.last_sequence.records)} if s.last_sequence else None,
            faults=[asdict(f) for f in s.faults],
            events=[asdict(e) for e in s.events[-10:]],
            loop_running=report.running,
            loop_failure=report.failure,
            realtime=asdict(report.realtime) if report.realtime else None,
        )

    def telemetry(self) -> Telemetry:
        """The latest cycle. The loop's lateness and compute percentiles are at most
        ``TELEMETRY_PERCENTILES_MAX_AGE_S`` old; counters and maxima are current."""
        report = self._host.report(TELEMETRY_PERCENTILES_MAX_AGE_S)
        s = report.snapshot
        stats = replace(report.stats, guard_clamps=s.clamped_cycles, fk_failures=s.fk_failures)
        return Telemetry(
            t=s.t_ns / 1e9,
            state=s.state.value,
            motion=s.motion.value,
            pose_command=_mm_deg(s.pose_command),
            pose_measured=_mm_deg(s.pose_measured) if s.pose_measured is not None else None,
            leg_setpoints=s.setpoints,
            leg_feedback=s.feedback.positions_mm if s.feedback else None,
            locked_leg=s.lock.leg if s.lock else None,
            calibration_id=s.active.calibration_id,
            sequence=_sequence_telemetry(s),
            faults=s.faults,
            loop=stats,
            realtime=report.realtime,
        )

    def events(self) -> tuple[Event, ...]:
        """The loop's recent events (faults, refusals, sequence and calibration changes)."""
        return self.snapshot.events

    def sequence_records(self) -> SequenceReport | None:
        """The playing or last played sequence's dwell records."""
        return self.snapshot.last_sequence

    def outcome(self, ticket: int) -> CommandResult | None:
        """The loop's verdict on command ``ticket`` (None if not carried out yet, or
        too long ago to be remembered)."""
        for outcome in reversed(self.snapshot.outcomes):
            if outcome.ticket == ticket:
                if outcome.code is None:
                    return CommandResult.success(outcome.message, ticket=ticket)
                return CommandResult.failure(outcome.code, outcome.message, ticket=ticket)
        return None

    # -- commands -------------------------------------------------------------------------

    def enable(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Energise the actuators and hold the pose they are at."""
        s = self.snapshot
        if refusal := check_enable(s, self.config.supervision.heartbeat_timeout_s):
            return CommandResult.failure(*refusal)
        return self._submit(cmd.Enable, "enabled", deadline_ns=deadline_ns)

    def disable(self) -> CommandResult:
        """Disable the actuators (at rest only: stop first)."""
        return self._checked(check_disable, cmd.Disable, "disabled")

    def stop(self) -> CommandResult:
        """Brake smoothly to rest where the motion happens to end; aborts a sequence."""
        return self._submit(cmd.Stop, "stopping")

    def estop(self) -> CommandResult:
        """Emergency stop, latched until reset. Sent from this thread at once where the
        actuators are reachable from here, and by the loop, which latches and repeats it."""
        sent = self._host.estop_now()
        result = self._submit(cmd.EStop, "E-stop latched")
        if sent is False:
            return CommandResult.failure(ErrorCode.SEND_FAILED, "the E-stop frame could not be sent; the loop "
                                         "latched ESTOP and keeps repeating it", **result.details)
        return result

    def reset(self) -> CommandResult:
        """Clear a latched FAULT or ESTOP: DISABLE and CLEAR_FAULT to all, state DISABLED."""
        return self._checked(check_reset, cmd.Reset, "reset to disabled")

    def validate_pose(self, pose: Sequence[float], duration: float | None = None,
                      speed: float | None = None) -> CommandResult:
        """Would :meth:`move` accept this? Plans and checks the whole path, moves nothing."""
        s = self.snapshot
        plan = plan_path(self._context(s), s.trajectory, [Waypoint(pose, duration, speed)])
        return _plan_result(plan, "valid")

    def move(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None, *,
             deadline_ns: int | None = None) -> CommandResult:
        """Move to ``pose`` (relative mm/deg), validated whole first; ``duration`` s (at
        least, to one loop period) or ``speed`` (0, 1] of the velocity limits. In
        leg-lock mode the goal is projected onto the locked leg's constraint (see
        ``details.goal``). A move while moving replaces the running one."""
        s = self.snapshot
        if refusal := check_move(s):
            return CommandResult.failure(*refusal)
        plan = plan_path(self._context(s), s.trajectory, [Waypoint(pose, duration, speed)])
        if not plan.ok:
            return _plan_result(plan, "")
        (segment,) = plan.segments
        return self._submit(lambda t: cmd.Move(t, s.epoch, segment), "moving", deadline_ns=deadline_ns,
                            **_plan_result(plan, "").details)

    def leg_lock(self, leg: int, *, deadline_ns: int | None = None) -> CommandResult:
        """Brake leg ``leg`` (1–6) at its current length; later moves keep it there."""
        if isinstance(leg, bool) or not isinstance(leg, (int, np.integer)) or not 1 <= leg <= 6:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"leg is a number from 1 to 6, got {leg!r}")
        return self._checked(check_lock, lambda t: cmd.LockLeg(t, int(leg)), f"leg {leg} locked", deadline_ns)

    def leg_unlock(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Release the locked leg; the pose being held becomes the target (no step)."""
        return self._checked(check_unlock, cmd.UnlockLeg, "unlocked", deadline_ns)

    def validate_sequence(self, sequence: MotionSequence | str) -> CommandResult:
        """Would :meth:`play` accept this sequence (or built-in name) from here? Plans and
        checks every waypoint's path, moves nothing."""
        resolved = _resolve_sequence(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self.snapshot
        return _plan_result(plan_path(self._context(s), s.trajectory, resolved.planning_waypoints()), "valid")

    def play(self, sequence: MotionSequence | str, *, deadline_ns: int | None = None) -> CommandResult:
        """Play a sequence, or a built-in one by name; every waypoint's path is validated
        before the first moves."""
        resolved = _resolve_sequence(sequence)
        if isinstance(resolved, CommandResult):
            return resolved
        s = self.snapshot
        if refusal := check_play(s):
            return CommandResult.failure(*refusal)
        plan = plan_path(self._context(s), s.trajectory, resolved.planning_waypoints())
        if not plan.ok:
            return _plan_result(plan, "")
        name = resolved.name
        return self._submit(lambda t: cmd.Play(t, s.epoch, name, plan.segments), f"playing {name}",
                            deadline_ns=deadline_ns, **_plan_result(plan, "").details)

    def pause(self) -> CommandResult:
        """Pause the sequence: brake to rest mid-move, or freeze the dwell's clock."""
        return self._checked(check_pause, cmd.Pause, "pausing")

    def resume(self, *, deadline_ns: int | None = None) -> CommandResult:
        """Continue a paused sequence; the rest of an interrupted move is planned and
        validated from where it stopped, at the segment's cruise speed."""
        s = self.snapshot
        if refusal := check_resume(s):
            return CommandResult.failure(*refusal)
        progress = s.sequence
        assert progress is not None
        remainder = None
        if progress.paused_in_move:
            segment = progress.segment
            waypoint = Waypoint(_mm_deg(segment.goal), None, segment.velocity_scale / segment.time_scale)
            plan = plan_path(self._context(s), s.trajectory, [waypoint])
            if not plan.ok:
                return _plan_result(plan, "")
            (remainder,) = plan.segments
        return self._submit(lambda t: cmd.Resume(t, s.epoch, remainder), "resumed", deadline_ns=deadline_ns)

    def abort(self) -> CommandResult:
        """End the sequence and brake to rest; its records are kept."""
        return self._checked(check_abort, cmd.Abort, "aborted")

    def load_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        """Validate a calibrated geometry and swap it in at a cycle boundary, ramping the
        set-points to it; refused with the reason otherwise (the active one stays)."""
        if not isinstance(geometry, Geometry):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "load_calibration takes a validated Geometry")
        if not isinstance(calibration_id, str) or not calibration_id:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "the calibration needs a non-empty id")
        if differences := limits_differences(geometry.limits, self.hardware_limits):
            return CommandResult.failure(
                ErrorCode.INVALID_GEOMETRY,
                "the calibration's [limits] differ from the hardware's (" + "; ".join(differences)
                + "): a calibration may change joints and zero lengths only; limits come from the nominal geometry",
                differences=differences,
            )
        return self._swap(ActiveGeometry.of(geometry, calibration_id, source), "loaded")

    def rollback_calibration(self) -> CommandResult:
        """Swap back to the previous calibration (validated and ramped like a load); the
        one rolled back from becomes the previous."""
        previous = self.snapshot.previous
        if previous is None:
            return CommandResult.failure(ErrorCode.NO_PREVIOUS_CALIBRATION, "there is no previous calibration")
        return self._swap(previous, "rolled back")

    # -- helpers ----------------------------------------------------------------------------

    def _context(self, s: CoreSnapshot) -> PlanningContext:
        config = self.config
        budget = s.active.geometry.limits.leg_velocity_mm_s * (1.0 - config.calibration_ramp_fraction)
        return PlanningContext(s.active, config.motion, config.loop.period_s, budget, s.lock,
                               config.lock_max_correction_mm, config.path_step_mm, config.path_step_deg,
                               config.lock_cycle_iterations)

    def _swap(self, new: ActiveGeometry, verb: str) -> CommandResult:
        """Check ``new``'s plausibility against the nominal geometry; dry-run it at the
        current pose, along the running move and the rest of the playing sequence, along
        the set-point ramp to it, and on the size of the set-point change; then hand it over."""
        s = self.snapshot
        if refusal := check_swap(s, new):
            return CommandResult.failure(*refusal)
        if problems := implausibilities(new.geometry, self.nominal):
            return CommandResult.failure(ErrorCode.INVALID_GEOMETRY,
                                         _implausible_message(f"calibration {new.calibration_id}", problems),
                                         implausible=problems)
        if refusal := self._ramp_refusal(s, new):
            return refusal
        path = [s.pose_command] + ([s.goal] if s.goal is not None else [])
        if s.sequence is not None:
            path += [segment.goal for segment in s.sequence.remaining]
        violations = assess_path(new.geometry, piecewise_line(path, self.config.path_step_mm, self.config.path_step_deg),
                                 0, self.config.path_step_mm, self.config.path_step_deg)
        if violations:
            return CommandResult.failure(ErrorCode.INVALID_GEOMETRY,
                                         f"calibration {new.calibration_id} refused: {violations[0].message}",
                                         violations=[asdict(v) for v in violations])
        change = max(abs(a - b) for a, b in zip(sensor_setpoints(new.geometry.legs, new.absolute(s.pose_command)),
                                                s.setpoints))
        if s.state is not ControlState.DISABLED and change > self.config.calibration_max_change_mm:
            return CommandResult.failure(ErrorCode.CALIBRATION_CHANGE_TOO_LARGE,
                                         f"calibration {new.calibration_id} would move a leg by {change:.2f} mm "
                                         f"(limit {self.config.calibration_max_change_mm:g} mm)", change_mm=change)
        return self._submit(lambda t: cmd.SwapGeometry(t, s.epoch, new), f"calibration {new.calibration_id} {verb}",
                            calibration_id=new.calibration_id, change_mm=change)

    def _ramp_refusal(self, s: CoreSnapshot, new: ActiveGeometry) -> CommandResult | None:
        """The refusal if a pose the platform passes through while the set-points ramp
        (linearly, core.ControlCore._swap) from those being sent to ``new``'s at the
        commanded pose leaves the limits, by the new geometry or by the active one (which
        of the two describes the machine is what the swap decides, so both must hold).
        ``RAMP_SAMPLES`` fractions; with set-points not all known (an actuator not heard
        from while disabled) there is nothing to ramp from, and nothing is checked."""
        if not all(isfinite(v) for v in s.setpoints):
            return None
        fractions = np.linspace(0.0, 1.0, RAMP_SAMPLES)
        start = np.array(s.setpoints)
        end = np.array(sensor_setpoints(new.geometry.legs, new.absolute(s.pose_command)))
        ramp = start + np.outer(fractions, end - start)
        guess = _mm_deg(s.pose_command)
        for model, which in ((new, "the new calibration"), (s.active, "the active one")):
            for fraction, assessment in zip(fractions, assess_readings(model.geometry, ramp, guess)):
                if assessment is None or assessment.violations:
                    problem = (assessment.violations[0].message if assessment is not None
                               else "the set-points have no pose (forward kinematics does not converge)")
                    return CommandResult.failure(
                        ErrorCode.INVALID_GEOMETRY,
                        f"calibration {new.calibration_id} refused: at ramp fraction {fraction:.2f} of the change to it, "
                        f"by {which}: {problem}; load it nearer the zero posture, or check the file",
                        ramp_fraction=float(fraction),
                        violations=[asdict(v) for v in assessment.violations] if assessment is not None else [])
        return None

    def _checked(self, check, factory: Callable[[int], cmd.Command], message: str,
                 deadline_ns: int | None = None) -> CommandResult:
        if refusal := check(self.snapshot):
            return CommandResult.failure(*refusal)
        return self._submit(factory, message, deadline_ns=deadline_ns)

    def _submit(self, factory: Callable[[int], cmd.Command], message: str, *, deadline_ns: int | None = None,
                **details: object) -> CommandResult:
        """Queue a command; with the loop running by itself, wait for its verdict. With
        ``deadline_ns`` (monotonic) the loop refuses it as ``expired`` once that has passed."""
        report = self._host.report(TELEMETRY_PERCENTILES_MAX_AGE_S)
        if report.failure is not None:
            return CommandResult.failure(ErrorCode.LOOP_FAILED, f"the control loop died: {report.failure}")
        ticket = next(self._tickets)
        self._host.submit(replace(factory(ticket), deadline_ns=deadline_ns))
        if not report.running:
            return CommandResult.success(message, ticket=ticket, pending=True, **details)
        deadline = time.monotonic() + self.config.command_timeout_s
        while time.monotonic() < deadline:
            verdict = self.outcome(ticket)
            if verdict is not None:
                return CommandResult(verdict.ok, verdict.error, message if verdict.ok else verdict.message,
                                     {**verdict.details, **details})
            time.sleep(self.config.loop.period_s / 2)
        return CommandResult.failure(ErrorCode.LOOP_TIMEOUT, "the loop gave no verdict in time; the command may still "
                                     "be carried out", ticket=ticket)


def _implausible_message(what: str, problems: Sequence[str]) -> str:
    return (f"{what} refused: it cannot be a calibration of this platform: " + "; ".join(problems)
            + ". A calibration identifies one machine of the nominal design, whose parameters lie within "
            "millimetres of the nominal ones: check that the file is this platform's calibration, identified "
            "from the nominal geometry in use; if the machine really differs this much from its design, "
            "describe it in a nominal geometry of its own")


def _resolve_sequence(sequence: object) -> MotionSequence | CommandResult:
    """A sequence, a built-in one by name, or the refusal."""
    if isinstance(sequence, str):
        if sequence not in BUILTIN_SEQUENCES:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"no built-in sequence {sequence!r}",
                                         builtin=list(BUILTIN_SEQUENCES))
        return builtin_sequence(sequence)
    if not isinstance(sequence, MotionSequence):
        return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "a sequence is a MotionSequence or a built-in name")
    return sequence


def _mm_deg(relative_mm_rad: Sequence[float]) -> tuple[float, ...]:
    return tuple(float(v) for v in pose_mm_rad_to_mm_deg(relative_mm_rad))


def _sequence_telemetry(s: CoreSnapshot) -> SequenceTelemetry | None:
    p = s.sequence
    return SequenceTelemetry(p.name, p.waypoint, p.total, p.phase.value) if p else None


def _plan_result(plan: Plan, message: str) -> CommandResult:
    if plan.refusal is not None:
        refusal = plan.refusal
        return CommandResult.failure(refusal.code, refusal.message, violations=[asdict(v) for v in refusal.violations],
                                     **refusal.details)
    return CommandResult.success(
        message,
        goal=list(_mm_deg(plan.segments[-1].goal)),
        duration_s=sum(seg.duration_s + seg.dwell_s for seg in plan.segments),
        waypoints=len(plan.segments),
    )
