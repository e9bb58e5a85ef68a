"""The loop's end of the commands from other threads: a few carried out per cycle, each answered.

Producers (:class:`~hexactl.control.host.LoopHost` in any thread) append to
:attr:`CommandInbox.queue`; ``deque.append``/``popleft`` are atomic in CPython, so there
is no lock the loop could wait on. Once a cycle the loop carries out at most
:data:`MAX_COMMANDS_PER_CYCLE` of them (the rest wait for the next cycle): a command
whose ``deadline_ns`` has passed is refused as ``expired``, any other goes to its
handler, and once carried out the command's own :meth:`~hexactl.control.commands.Command.event`
is noted. Every command (but a stream's targets: ``answered`` False) gets an :class:`~hexactl.control.commands.Outcome` (the last
:data:`KEPT_OUTCOMES` are kept for the snapshot); a refusal is also logged.

Owned by the loop thread apart from ``queue.append``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping

from hexactl.control import commands as cmd
from hexactl.control.preconditions import Refusal
from hexactl.control.results import ErrorCode

MAX_COMMANDS_PER_CYCLE = 8
"""Commands carried out per cycle at most; the rest wait for the next cycle."""

KEPT_OUTCOMES = 64
"""Recent command outcomes kept for the snapshot."""

Handler = Callable[[cmd.Command], Refusal | cmd.CarriedOut]


class CommandInbox:
    """Commands waiting for the loop; ``handlers`` carry out each command type (the
    refusal, or None or a :class:`~hexactl.control.commands.CarriedOut` when done);
    ``log(code, message)`` notes refusals and the commands' own events. While a command
    is carried out, :attr:`sender` is its sender (else None): every event noted meanwhile,
    by its handler too, is that sender's doing."""

    def __init__(self, handlers: Mapping[type[cmd.Command], Handler], log: Callable[[str, str], None]) -> None:
        self.queue: deque[cmd.Command] = deque()
        self.outcomes: tuple[cmd.Outcome, ...] = ()
        self.sender: str | None = None
        self._handlers = handlers
        self._log = log

    def run(self, now_ns: int) -> None:
        """Carry out the commands waiting at monotonic time ``now_ns``, a bounded number."""
        queue = self.queue
        for _ in range(MAX_COMMANDS_PER_CYCLE):
            if not queue:
                break
            self._execute(queue.popleft(), now_ns)

    def _execute(self, command: cmd.Command, now_ns: int) -> None:
        self.sender = command.sender
        try:
            self._carry_out(command, now_ns)
        finally:
            self.sender = None

    def _carry_out(self, command: cmd.Command, now_ns: int) -> None:
        deadline_ns = command.deadline_ns
        if deadline_ns is not None and now_ns > deadline_ns:
            verdict: Refusal | cmd.CarriedOut = ErrorCode.EXPIRED, (
                f"its deadline passed {(now_ns - deadline_ns) / 1e6:.1f} ms before the loop reached it; "
                "not carried out: send it again with a longer timeout if it is still wanted")
        else:
            verdict = self._handlers[type(command)](command)
        if verdict is None:  # the common case first: a stream's target every cycle
            code, message = None, cmd.DONE
        elif isinstance(verdict, cmd.CarriedOut):
            code, message = None, verdict.message
        else:
            code, message = verdict
        if code is not None:
            self._log("command_refused", f"{type(command).__name__}: {message}")
        elif (event := command.event()) is not None:
            self._log(*event)
        if not command.answered:
            return
        self.outcomes = (self.outcomes + (cmd.Outcome(command.ticket, code, message),))[-KEPT_OUTCOMES:]
