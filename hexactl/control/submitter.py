"""Handing commands to the loop and reading its verdicts, by ticket."""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import replace

from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.host import LoopHost
from hexactl.control.preconditions import Refusal
from hexactl.control.results import REPORT_SILENT_S, CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.telemetry import PERCENTILES_MAX_AGE_S

SILENCE_RECHECK_S = 0.1
"""s: how long a command to a loop that seems silent waits for a report to show up before
it is refused ``loop_silent`` (:meth:`CommandSubmitter._silent_s`)."""

# A context variable rather than a parameter: who sent a request is the request's context,
# like a log's, and no business of the thirty controller methods between it and the loop.
_SENDER: ContextVar[str | None] = ContextVar("hexactl_command_sender", default=None)


@contextmanager
def commands_from(sender: str | None) -> Iterator[None]:
    """Within it, the commands this thread (this context) submits carry ``sender``, who
    sent them for people (:attr:`~hexactl.control.commands.Command.sender`)."""
    token = _SENDER.set(sender)
    try:
        yield
    finally:
        _SENDER.reset(token)


class CommandSubmitter:
    """Queues commands on ``host`` with tickets from ``ticket_start`` on (facades sharing
    one loop take disjoint ranges: outcomes are found by ticket) and, with the loop running
    by itself, waits at most ``config.command_timeout_s`` for each verdict."""

    def __init__(self, host: LoopHost, config: ControllerConfig, ticket_start: int = 1) -> None:
        self._host = host
        self._config = config
        self._tickets = itertools.count(ticket_start)  # next() on a count is atomic in CPython
        self._silent_on: CoreSnapshot | None = None  # the latest report when a silence was last confirmed

    def outcome(self, ticket: int) -> CommandResult | None:
        """The loop's verdict on command ``ticket`` (None if not carried out yet, or too
        long ago to be remembered)."""
        for outcome in reversed(self._host.snapshot.outcomes):
            if outcome.ticket == ticket:
                if outcome.code is None:
                    return CommandResult.success(outcome.message, ticket=ticket)
                return CommandResult.failure(outcome.code, outcome.message, ticket=ticket)
        return None

    def submit_unless(self, check: Callable[[CoreSnapshot], Refusal], factory: Callable[[int], cmd.Command],
                      message: str, *, deadline_ns: int | None = None) -> CommandResult:
        """:meth:`submit`, unless ``check`` refuses it on the loop's latest snapshot (the
        loop checks again when it carries it out)."""
        if refusal := check(self._host.snapshot):
            return CommandResult.failure(*refusal)
        return self.submit(factory, message, deadline_ns=deadline_ns)

    def submit(self, factory: Callable[[int], cmd.Command], message: str, *, deadline_ns: int | None = None,
               **details: object) -> CommandResult:
        """Queue the command ``factory`` builds for its ticket; with the loop running by
        itself, wait for its verdict (``details`` join an accepted one, and ``message`` unless
        its handler told what it did: :class:`~hexactl.control.commands.CarriedOut`).
        With ``deadline_ns`` (monotonic) the loop refuses it as ``expired`` once that has
        passed. It carries the sender of :func:`commands_from`. ``loop_failed`` if the loop died;
        ``loop_silent`` if it has not reported for :data:`REPORT_SILENT_S`
        (:meth:`_to_silent_loop`); ``loop_timeout`` if no verdict came in time."""
        report = self._host.report(PERCENTILES_MAX_AGE_S)  # only its liveness is read
        if report.failure is not None:
            return CommandResult.failure(ErrorCode.LOOP_FAILED, f"the control loop died: {report.failure}")
        ticket = next(self._tickets)
        command = replace(factory(ticket), deadline_ns=deadline_ns, sender=_SENDER.get())
        if report.stats.report_age_s > REPORT_SILENT_S and (silent_s := self._silent_s(report.stats.report_age_s)) \
                is not None:
            return self._to_silent_loop(command, silent_s)
        self._host.submit(command)
        if not report.running:
            return CommandResult.success(message, ticket=ticket, pending=True, **details)
        deadline = time.monotonic() + self._config.command_timeout_s
        while time.monotonic() < deadline:
            verdict = self.outcome(ticket)
            if verdict is not None:
                told = not verdict.ok or verdict.message != cmd.DONE  # the loop's word over the snapshot's
                return CommandResult(verdict.ok, verdict.error, verdict.message if told else message,
                                     {**verdict.details, **details})
            time.sleep(self._config.loop.period_s / 2)
        return self._unconfirmed(command)

    def _unconfirmed(self, command: cmd.Command) -> CommandResult:
        """``loop_timeout`` for ``command``, queued to a loop that gave no verdict within
        ``command_timeout_s``. One that still reports runs late (a host too busy for it): the
        command is carried out when the loop reaches it, unless its deadline has passed by
        then. A command that brakes has none and is said to be on its way: a stop or E-stop
        answered "may still be carried out" reads, at the worst moment, as one that may not
        be. One that has stopped reporting meanwhile (hung) carries out nothing until it
        runs again: that is said instead."""
        age_s = self._host.report(PERCENTILES_MAX_AGE_S).stats.report_age_s
        if age_s > REPORT_SILENT_S:
            return CommandResult.failure(ErrorCode.LOOP_TIMEOUT, f"queued, to be carried out if the loop runs again: "
                                         f"{_silence(age_s)}", ticket=command.ticket)
        late = (f"the loop gave no verdict within {self._config.command_timeout_s:g} s (it runs late: a host too "
                "busy for it?)")
        if command.brakes:
            message = (f"queued, not confirmed yet: {late}; the loop carries it out when it reaches it, and "
                       "status shows it carried out")
        else:
            message = f"{late}; the command may still be carried out: see status before sending it again"
        return CommandResult.failure(ErrorCode.LOOP_TIMEOUT, message, ticket=command.ticket)

    def settled(self, problem: Callable[[CoreSnapshot], str | None], timeout_s: float) -> str | None:
        """None once ``problem`` finds nothing in the loop's latest snapshot, asked every half
        loop period; what it still finds after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while (found := problem(self._host.snapshot)) is not None and time.monotonic() < deadline:
            time.sleep(self._config.loop.period_s / 2)
        return found

    def _silent_s(self, age_s: float) -> float | None:
        """How long the loop has sent no report (``age_s`` when last seen), asked again while
        this thread lets the others run for :data:`SILENCE_RECHECK_S` (None: a report came
        meanwhile). If the host held up this process rather than the loop's, its reports wait
        to be read by a thread of this one, which needs a turn. A silence confirmed with no
        report since is not asked again: a client repeating ``stop`` to a stopped loop would
        otherwise hold up, for each, the thread that answers every other client."""
        if self._host.snapshot is self._silent_on:
            return age_s
        deadline = time.monotonic() + SILENCE_RECHECK_S
        while True:
            time.sleep(self._config.loop.period_s / 2)
            if (age_s := self._host.report(PERCENTILES_MAX_AGE_S).stats.report_age_s) <= REPORT_SILENT_S:
                return None
            if time.monotonic() >= deadline:
                self._silent_on = self._host.snapshot
                return age_s

    def _to_silent_loop(self, command: cmd.Command, silent_s: float) -> CommandResult:
        """``loop_silent`` for ``command`` to a loop that has sent no report for ``silent_s``:
        its process is stopped or hung, and no verdict would come. A command that only
        brakes (:attr:`~hexactl.control.commands.Command.brakes`) is queued all the same, for
        if it runs again; any other is not sent (it would run whenever the loop does)."""
        silence = _silence(silent_s)
        if not command.brakes:
            return CommandResult.failure(ErrorCode.LOOP_SILENT, f"not sent: {silence}; see status")
        self._host.submit(command)
        return CommandResult.failure(ErrorCode.LOOP_SILENT, f"queued, to be carried out if the loop runs again: "
                                     f"{silence}", ticket=command.ticket)


def _silence(silent_s: float) -> str:
    """What a loop that has sent no report for ``silent_s`` means for the platform."""
    return (f"the control loop has sent no report for {silent_s:.1f} s (its process is stopped or hung); "
            "actuators that receive no set-points stop on their own watchdogs")
