"""Jog in the loop: a motion that goes on only while its client keeps renewing it.

The facade plans a jog (:mod:`hexactl.control.jog_planning`) as a move along the
requested velocity to the first limit ahead, or to a horizon that renewals push on, at
the requested speed: the trajectory generator accelerates to that speed and, if nothing
stops it first, decelerates to rest exactly on the limit. Nothing about a limit is
refused or clamped mid-motion: the plan ends there.

:class:`Jogger` is the loop's deadman: a renewal moves the deadline on by the
configured interval; once a cycle finds it passed (the client released the button, lost
its connection or stalled), the trajectory brakes to rest along its path, jerk-limited
(:meth:`~hexactl.control.trajectory.PoseTrajectory.halt`), and the jog ends when at rest.

Times monotonic ns. Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import StrEnum

from hexactl.control.planning import Segment
from hexactl.control.results import DEADMAN_LAPSED, ErrorCode, jog_ended_message
from hexactl.control.trajectory import PoseTrajectory


@dataclass(frozen=True, slots=True)
class JogPlan:
    """A planned jog: ``velocity`` (mm/s for x, y, z; deg/s for roll, pitch, yaw) in
    ``frame`` (a :class:`~hexactl.control.frames.Frame` value) as requested; ``segment``
    the move that carries it out; ``speed`` its velocity scale, as a move's: the fraction
    of the motion limits that ``velocity`` is (1: the limits, when it asks as much or
    more, and then it runs slower than asked); ``end`` why the segment ends where it does,
    for people; ``to_limit`` True when that is a limit (False: the horizon, which a
    renewal extends); ``deadman_ns`` how long each renewal lasts."""

    frame: str
    velocity: tuple[float, ...]
    segment: Segment
    speed: float
    end: str
    to_limit: bool
    deadman_ns: int


class JogPhase(StrEnum):
    JOGGING = "jogging"  # moving along the jog's direction
    AT_END = "at_end"  # at rest where the plan ends: on the limit, or at the horizon (see ``to_limit``)
    BRAKING = "braking"  # released, replaced or lapsed: braking to rest


@dataclass(frozen=True, slots=True)
class JogProgress:
    """The jog under way as published: ``jog`` its number (the ticket that started it),
    ``phase``, ``deadline_ns`` (monotonic) when the deadman lapses unless renewed, and the
    plan's request and end (:class:`JogPlan`); ``reason`` why it brakes (None until it does)."""

    jog: int
    frame: str
    velocity: tuple[float, ...]
    speed: float
    phase: JogPhase
    end: str
    to_limit: bool
    deadline_ns: int
    reason: str | None = None


@dataclass(frozen=True, slots=True)
class JogReport:
    """How the last jog ended: ``reason`` for people."""

    jog: int
    reason: str


def restartable(progress: JogProgress | None, report: JogReport | None, jog: int) -> bool:
    """Whether jog ``jog``, of the jog under way ``progress`` and the last one ended
    ``report``, may be restarted by its client: its deadman lapsed (the client was late) and
    nothing came since, or it is still under way."""
    if progress is not None and progress.jog == jog:
        return progress.phase is not JogPhase.BRAKING or progress.reason == DEADMAN_LAPSED
    return progress is None and report is not None and report.jog == jog and report.reason == DEADMAN_LAPSED


class Jogger:
    """The deadman of the jog running on ``trajectory``; ``log(code, message)`` notes
    starts, arrivals and ends."""

    def __init__(self, trajectory: PoseTrajectory, log: Callable[[str, str], None]) -> None:
        self._trajectory = trajectory
        self._log = log
        self._deadman_ns = 0
        self.progress: JogProgress | None = None
        """The jog under way as published; made when it changes, not every cycle."""
        self.report: JogReport | None = None
        """How the last jog ended."""

    def start(self, jog: int, plan: JogPlan, now_ns: int) -> None:
        """Jog ``jog`` runs ``plan`` (its segment already started), renewed until ``now_ns``
        plus the deadman interval: a new jog, or the one under way re-planned (logged only
        when its number is new: a jog held for minutes is re-planned every few seconds)."""
        self._deadman_ns = plan.deadman_ns
        known = self.progress is not None and self.progress.jog == jog
        if not known:  # the one under way or braking (why, kept), or a lapse nothing came after, is replaced
            braking = self.progress.reason if self.progress is not None else None
            self.end(f"{braking}, then replaced by jog {jog}" if braking else f"replaced by jog {jog}")
        self.progress = JogProgress(jog, plan.frame, plan.velocity, plan.speed, JogPhase.JOGGING, plan.end,
                                    plan.to_limit, now_ns + plan.deadman_ns)
        if not known:
            self._log("jog_started", f"jog {jog}: {plan.frame} frame, velocity {list(plan.velocity)}; ends at "
                      f"{plan.end}")

    def ended(self, jog: int) -> tuple[ErrorCode, str] | None:
        """Why jog ``jog`` cannot be renewed or extended (it is not under way, or it brakes);
        None if it can."""
        progress, report = self.progress, self.report
        if progress is not None and progress.jog == jog:
            return None if progress.phase is not JogPhase.BRAKING else (ErrorCode.JOG_ENDED,
                                                                          jog_ended_message(jog, progress.reason))
        reason = report.reason if report is not None and report.jog == jog else None
        return ErrorCode.JOG_ENDED, jog_ended_message(jog, reason)

    def renew(self, jog: int, frame: str, velocity: tuple[float, ...], now_ns: int) -> tuple[ErrorCode, str] | None:
        """Move the deadline on, if the jog under way is ``jog``, at this velocity and frame,
        and not braking."""
        if refusal := self.ended(jog):
            return refusal
        progress = self.progress
        assert progress is not None
        if progress.frame != frame or progress.velocity != velocity:
            return ErrorCode.JOG_ENDED, "the jog under way has another velocity or frame: send jog again to change it"
        self.progress = replace(progress, deadline_ns=now_ns + self._deadman_ns)
        return None

    def brake(self, reason: str) -> None:
        """End the jog: brake to rest (the caller halts the trajectory), then it ends as ``reason``."""
        progress = self.progress
        if progress is not None and progress.phase is not JogPhase.BRAKING:
            self.progress = replace(progress, phase=JogPhase.BRAKING, reason=reason)
        else:
            self._overrule_lapse(reason)

    def end(self, reason: str) -> None:
        """End the jog at once (the motion was taken over or frozen)."""
        if self.progress is not None:
            self.report = JogReport(self.progress.jog, reason)
            self._log("jog_ended", f"jog {self.progress.jog}: {reason}")
            self.progress = None
        else:
            self._overrule_lapse(reason)

    def _overrule_lapse(self, reason: str) -> None:
        """A jog whose deadman lapsed (its client late: a held button may start it again)
        that anything else then stops or takes over ends as that instead: its client's next
        renewal is refused for good. Else a stop that came while a late client's jog lapsed
        was followed by that client starting a new jog, which ran on."""
        progress, report = self.progress, self.report
        if progress is not None and progress.reason == DEADMAN_LAPSED:
            self.progress = replace(progress, reason=reason)
        elif progress is None and report is not None and report.reason == DEADMAN_LAPSED:
            self.report = JogReport(report.jog, reason)

    def before_step(self, now_ns: int) -> None:
        """Brake if the deadman lapsed by ``now_ns``."""
        progress = self.progress
        if progress is not None and progress.phase is not JogPhase.BRAKING and now_ns >= progress.deadline_ns:
            self._trajectory.halt()
            self.brake(DEADMAN_LAPSED)

    def after_step(self) -> None:
        """After this cycle's trajectory update: arrive at the plan's end, or end once
        braked to rest."""
        progress = self.progress
        if progress is None:
            return
        if progress.phase is JogPhase.JOGGING and not self._trajectory.moving:
            self.progress = replace(progress, phase=JogPhase.AT_END)
            self._log("jog_at_end", f"jog {progress.jog} at rest at {progress.end}")
        elif progress.phase is JogPhase.BRAKING and not self._trajectory.moving:
            self.end(progress.reason or "")
