"""The facade's jog command: start, renew, re-plan or release a jog (:mod:`hexactl.control.jog`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from math import isfinite

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.bounds import jog_velocity_problem
from hexactl.control.frames import Frame, convert
from hexactl.control.jog import JogPhase, restartable
from hexactl.control.jog_planning import JOG_EXTEND_S, plan_jog
from hexactl.control.planning import PlanningContext, Refusal
from hexactl.control.results import DEADMAN_LAPSED, CommandResult, ErrorCode, jog_ended_message
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.telemetry import motion_remaining_s

class JogCommands:
    """Jogs of one facade: ``snapshot()`` the loop's latest, ``context(snapshot)`` what a plan
    depends on, commands queued by ``submitter``; each renewal lasts ``deadman_s``."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], context: Callable[[CoreSnapshot], PlanningContext],
                 submitter: CommandSubmitter, deadman_s: float) -> None:
        self._snapshot = snapshot
        self._context = context
        self._submitter = submitter
        self.deadman_s = deadman_s

    def jog(self, velocity: Sequence[float], frame: Frame, deadline_ns: int | None,
            renews: int | None = None, restarts: int | None = None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.jog`."""
        if problem := (_velocity_problem(velocity) or (None if frame in tuple(Frame) else f"unknown frame {frame!r}")
                       or ("renews or restarts, not both: a renewal names the jog under way, a restart the one "
                           "whose deadman lapsed" if renews is not None and restarts is not None else None)):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, problem)
        velocity, frame = tuple(float(v) for v in velocity), Frame(frame)
        s = self._snapshot()
        if not any(velocity):
            return self._release()
        if refusal := preconditions.check_jog(s):
            return CommandResult.failure(*refusal)
        if restarts is not None:
            return self._restart(s, restarts, velocity, frame, deadline_ns)
        current = s.jog
        if renews is not None and (current is None or current.jog != renews or current.phase is JogPhase.BRAKING):
            last = s.last_jog
            if (current is not None and current.jog == renews) or (last is not None and last.jog == renews):
                return _ended(s, renews)
            # Not in the snapshot, which lags the loop by up to a report (a jog just started): the loop tells.
            return self._renew(renews, frame, velocity, deadline_ns, jog=renews, deadman_s=self.deadman_s)
        same = (current is not None and current.phase is not JogPhase.BRAKING and current.frame == frame.value
                and current.velocity == velocity)
        if same and (current.to_limit or (motion_remaining_s(s) or 0.0) > JOG_EXTEND_S):
            return self._renew(current.jog, frame, velocity, deadline_ns,
                               **_details(current.jog, current.speed, current.end, current.to_limit, self.deadman_s))
        # a renewal near the plan's end: the same jog, planned on
        return self._start(s, velocity, frame, deadline_ns, continues=current.jog if same else None)

    def _start(self, s: CoreSnapshot, velocity: tuple[float, ...], frame: Frame, deadline_ns: int | None,
               continues: int | None = None, restarts: int | None = None) -> CommandResult:
        """Plan a jog from ``s`` and start it (see :class:`~hexactl.control.commands.Jog`)."""
        plan = plan_jog(self._context(s), s.trajectory, s.frames, velocity, frame, round(self.deadman_s * 1e9))
        if isinstance(plan, Refusal):
            return plan.result()
        goal = convert(plan.segment.goal, plan.segment.frames, None, s.active.home).in_degrees()
        result = self._submitter.submit(lambda t: cmd.Jog(t, s.epoch, plan, continues, restarts), "jogging",
                                        deadline_ns=deadline_ns, goal=list(goal),
                                        **_details(None, plan.speed, plan.end, plan.to_limit, self.deadman_s))
        # a jog's number is the ticket of the command that started it
        number = result.details.get("ticket") if continues is None else continues
        return replace(result, details={"jog": number, **result.details})

    def _restart(self, s: CoreSnapshot, lapsed: int, velocity: tuple[float, ...], frame: Frame,
                 deadline_ns: int | None) -> CommandResult:
        """A new jog in place of jog ``lapsed``, whose deadman lapsed, unless something (a
        stop from anyone) came after the lapse: then refused ``jog_ended`` for good, by the
        facade on its snapshot or by the loop, which has the last word."""
        if not restartable(s.jog, s.last_jog, lapsed):
            return _ended(s, lapsed)
        result = self._start(s, velocity, frame, deadline_ns, restarts=lapsed)
        if result.error != ErrorCode.JOG_ENDED:
            return result
        ended = _ended(self._snapshot(), lapsed)  # the snapshot may not show yet what came after the lapse
        return ended if not ended.details["lapsed"] else replace(
            result, details={**result.details, "jog": lapsed, "reason": None, "lapsed": False})

    def _renew(self, number: int, frame: Frame, velocity: tuple[float, ...], deadline_ns: int | None,
               **details: object) -> CommandResult:
        """Renew jog ``number``; refused ``jog_ended`` by the loop (it ended since the snapshot
        the facade checked), with why from the snapshot that came with the verdict, as a
        refusal the facade makes itself says: a lapse there lacked ``details.lapsed``, and the
        dashboard released the held button for good where a lapse lets it jog again."""
        result = self._submitter.submit(lambda t: cmd.RenewJog(t, number, frame.value, velocity), "jog renewed",
                                        deadline_ns=deadline_ns, **details)
        if result.error != ErrorCode.JOG_ENDED:
            return result
        ended = _ended(self._snapshot(), number)
        return ended if ended.details["reason"] is not None else replace(
            result, details={**result.details, "reason": None, "lapsed": False})

    def _release(self) -> CommandResult:
        """Release the jog under way: sent to the loop whatever the snapshot says (it may not
        show yet a jog just started), which brakes only a jog (another's move goes on) and
        says what it released."""
        return self._submitter.submit(cmd.ReleaseJog, "release sent: the loop carries it out when it runs")


def _ended(s: CoreSnapshot, jog: int) -> CommandResult:
    """The refusal of a renewal of ``jog``, which brakes or has ended (the snapshot says
    so): ``details.reason`` why, ``details.lapsed`` whether its deadman lapsed (its client
    was late: a held button may start a new jog; after anything else it is released)."""
    current, last = s.jog, s.last_jog
    reason = (current.reason if current is not None and current.jog == jog
              else last.reason if last is not None and last.jog == jog else None)
    return CommandResult.failure(ErrorCode.JOG_ENDED, jog_ended_message(jog, reason), jog=jog, reason=reason,
                                 lapsed=reason == DEADMAN_LAPSED)


def _velocity_problem(velocity: object) -> str | None:
    values = list(velocity) if isinstance(velocity, (list, tuple)) else None
    if values is None or len(values) != 6:
        return "a jog velocity is six numbers: x, y, z in mm/s and roll, pitch, yaw in deg/s"
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not isfinite(value):
            return f"a jog velocity's components are finite numbers, got {value!r}"
    return jog_velocity_problem(values)


def _details(jog: int | None, speed: float, end: str, to_limit: bool, deadman_s: float) -> dict[str, object]:
    return {"speed": speed, "end": end, "to_limit": to_limit, "deadman_s": deadman_s,
            **({"jog": jog} if jog is not None else {})}
