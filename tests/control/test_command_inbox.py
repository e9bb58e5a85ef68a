"""The loop's command inbox alone: a bounded number per cycle, deadlines, one outcome per
ticket, refusals logged."""

from __future__ import annotations

from hexactl.control import commands as cmd
from hexactl.control.command_inbox import KEPT_OUTCOMES, MAX_COMMANDS_PER_CYCLE, CommandInbox
from hexactl.control.results import ErrorCode


class Rig:
    def __init__(self) -> None:
        self.done: list[int] = []
        self.log: list[tuple[str, str]] = []
        self.inbox = CommandInbox({cmd.Stop: self._stop, cmd.Reset: self._refuse},
                                  lambda code, message: self.log.append((code, message)))

    def _stop(self, command: cmd.Stop):
        self.done.append(command.ticket)
        return None

    def _refuse(self, command: cmd.Reset):
        return ErrorCode.NOT_LATCHED, "nothing to reset"


def test_a_bounded_number_per_cycle_in_order_the_rest_waits():
    rig = Rig()
    rig.inbox.queue.extend(cmd.Stop(t) for t in range(MAX_COMMANDS_PER_CYCLE + 3))
    rig.inbox.run(0)
    assert rig.done == list(range(MAX_COMMANDS_PER_CYCLE)) and len(rig.inbox.queue) == 3
    rig.inbox.run(1)
    assert rig.done == list(range(MAX_COMMANDS_PER_CYCLE + 3)) and not rig.inbox.queue
    assert [o.ticket for o in rig.inbox.outcomes] == rig.done
    assert all(o.code is None and o.message == "done" for o in rig.inbox.outcomes)


def test_a_refusal_is_the_outcome_and_is_logged():
    rig = Rig()
    rig.inbox.queue.append(cmd.Reset(7))
    rig.inbox.run(0)
    assert rig.inbox.outcomes == (cmd.Outcome(7, ErrorCode.NOT_LATCHED, "nothing to reset"),)
    assert rig.log == [("command_refused", "Reset: nothing to reset")]


def test_a_command_past_its_deadline_expires_without_being_carried_out():
    rig = Rig()
    rig.inbox.queue.extend([cmd.Stop(1, deadline_ns=1_000), cmd.Stop(2, deadline_ns=3_500_000)])
    rig.inbox.run(1_000)  # on the deadline: still wanted
    rig.inbox.queue.append(cmd.Stop(3, deadline_ns=1_000))
    rig.inbox.run(2_500_000)
    assert rig.done == [1, 2]
    outcome = rig.inbox.outcomes[-1]
    assert (outcome.ticket, outcome.code) == (3, ErrorCode.EXPIRED)
    assert "2.5 ms" in outcome.message and "send it again" in outcome.message
    assert rig.log[-1][0] == "command_refused"


def test_the_last_outcomes_are_kept():
    rig = Rig()
    for ticket in range(KEPT_OUTCOMES + 5):
        rig.inbox.queue.append(cmd.Stop(ticket))
        rig.inbox.run(0)
    assert [o.ticket for o in rig.inbox.outcomes] == list(range(5, KEPT_OUTCOMES + 5))


def test_a_handler_may_say_what_it_did_and_the_outcome_carries_it():
    rig = Rig()
    rig.inbox = CommandInbox({cmd.ReleaseJog: lambda command: cmd.CarriedOut("jog 4 released")},
                             lambda code, message: rig.log.append((code, message)))
    rig.inbox.queue.append(cmd.ReleaseJog(9))
    rig.inbox.run(0)
    assert rig.inbox.outcomes == (cmd.Outcome(9, None, "jog 4 released"),)
    assert rig.log == []  # carried out: not a refusal
