"""The facade's wave commands: validate or play a wave (:mod:`hexactl.control.wave_planning`)."""

from __future__ import annotations

from collections.abc import Callable

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.planning import PlanningContext, Refusal
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.control.wave_planning import WavePlan, plan_wave
from hexactl.control.waves import WaveSpec


class WaveCommands:
    """Waves of one facade: ``snapshot()`` the loop's latest, ``context(snapshot)`` what a
    plan depends on, commands queued by ``submitter``."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], context: Callable[[CoreSnapshot], PlanningContext],
                 submitter: CommandSubmitter) -> None:
        self._snapshot = snapshot
        self._context = context
        self._submitter = submitter

    def validate(self, spec: WaveSpec) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.validate_wave`. Not the state,
        as every validation; but with a leg locked the message says that its figures are the
        wave's with all six legs free, which :meth:`play` needs (a plain "valid" beside a
        locked leg's speed read as a wave that runs braked)."""
        s = self._snapshot()
        locked = "" if s.lock is None else (f" with all six legs free: leg {s.lock.leg} is locked, and wave is refused "
                                            "until it is unlocked")
        return _result(self._plan(s, spec), f"valid{locked}")

    def play(self, spec: WaveSpec, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.wave`."""
        s = self._snapshot()
        if refusal := preconditions.check_wave(s):
            return CommandResult.failure(*refusal)
        plan = self._plan(s, spec)
        if not isinstance(plan, WavePlan):
            return _result(plan, "")
        return self._submitter.submit(lambda t: cmd.PlayWave(t, s.epoch, plan), "waving", deadline_ns=deadline_ns,
                                      **plan.summary())

    def _plan(self, s: CoreSnapshot, spec: WaveSpec) -> WavePlan | Refusal:
        if not isinstance(spec, WaveSpec):
            return Refusal(ErrorCode.INVALID_ARGUMENT, "a wave is a WaveSpec")
        return plan_wave(self._context(s), s.target, s.frames, spec)


def _result(plan: WavePlan | Refusal, message: str) -> CommandResult:
    """The refusal (its violations and details), or ``message`` with the plan's figures."""
    if isinstance(plan, Refusal):
        return plan.result()
    return CommandResult.success(message, **plan.summary())
