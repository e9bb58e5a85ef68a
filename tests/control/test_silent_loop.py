"""Commands to a loop that has stopped reporting (control/submitter.py): past
``REPORT_SILENT_S`` without a report, its process is stopped or hung; a command is not sent
(``loop_silent``: it would run whenever the loop does), except one that only brakes,
which is queued for if it runs again. A report that shows up within a moment (this
process was the one held up) is no silence."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import pytest

from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.controller import Controller
from hexactl.control.host import LoopReport, LoopThread
from hexactl.control.results import REPORT_SILENT_S


@dataclass
class AgedHost:
    """``thread`` seen through reports as old as ``ages`` says (s), one a report, the last
    one repeated; what is submitted is kept in ``submitted`` (the loop is not stepped)."""

    thread: LoopThread
    ages: list[float]
    running: bool | None = None  # what the reports say of it (None: as it is)
    submitted: list[cmd.Command] = field(default_factory=list)
    reports: int = 0

    @property
    def snapshot(self):
        return self.thread.snapshot

    def report(self, stats_max_age_s: float) -> LoopReport:
        self.reports += 1
        report = self.thread.report(stats_max_age_s)
        age = self.ages.pop(0) if len(self.ages) > 1 else self.ages[0]
        report = replace(report, stats=replace(report.stats, report_age_s=age))
        return report if self.running is None else replace(report, running=self.running)

    def submit(self, command: cmd.Command) -> None:
        self.submitted.append(command)

    def estop_now(self) -> None:
        return None

    def take_recorded(self) -> list:
        return []


def facade(rig, ages: list[float], running: bool | None = None,
           config: ControllerConfig | None = None) -> tuple[Controller, AgedHost]:
    host = AgedHost(rig.controller.thread, ages, running)
    return Controller(host, config=config or ControllerConfig(), nominal=rig.geometry), host


def test_a_silent_loop_is_sent_only_what_brakes(rig) -> None:
    controller, host = facade(rig, [REPORT_SILENT_S + 4.0])
    refused = controller.enable()
    assert refused.error == "loop_silent" and host.submitted == []
    assert refused.message.startswith("not sent: the control loop has sent no report for 5.0 s (its process is "
                                      "stopped or hung)"), refused.message
    for brake, kind in ((controller.stop, cmd.Stop), (controller.estop, cmd.EStop)):
        queued = brake()
        assert queued.error == "loop_silent" and queued.message.startswith("queued, to be carried out if the loop "
                                                                           "runs again"), queued
        assert type(host.submitted[-1]) is kind and queued.details["ticket"] == host.submitted[-1].ticket
    assert len(host.submitted) == 2


@pytest.mark.parametrize("ages", [[REPORT_SILENT_S - 0.01], [REPORT_SILENT_S + 4.0, 0.002]],
                         ids=["under a second", "a report read meanwhile"])
def test_a_loop_that_reports_is_sent_everything(rig, ages: list[float]) -> None:
    controller, host = facade(rig, ages)
    queued = controller.enable()
    assert queued.ok and queued.details["pending"], queued  # the loop is not running: no verdict awaited
    assert [type(command) for command in host.submitted] == [cmd.Enable]


def test_a_silence_confirmed_is_not_waited_for_again_until_a_report_comes(rig) -> None:
    """Each stop to a stopped loop waited SILENCE_RECHECK_S for a report, in the thread that
    answers every client: one repeating stop held up the others' status for seconds."""
    controller, host = facade(rig, [REPORT_SILENT_S + 4.0])
    assert controller.stop().error == "loop_silent"
    rechecked = host.reports
    assert rechecked > 2  # the first one asked again, waiting
    for _ in range(3):
        assert controller.stop().error == "loop_silent"
    assert host.reports == rechecked + 3  # one look each: no report came since the silence was confirmed
    rig.run()  # a report: what comes next may be this process held up again
    assert controller.stop().error == "loop_silent" and host.reports > rechecked + 5


def test_a_late_loops_stop_and_estop_are_said_to_be_on_their_way(rig) -> None:
    """A loop that reports but runs late (a host too busy for it) gives no verdict in time.
    A stop or E-stop answered "the command may still be carried out" read, at the worst
    moment, as one that may not be: it is queued, and said so."""
    controller, host = facade(rig, [0.002], running=True, config=ControllerConfig(command_timeout_s=0.05))
    for brake, kind in ((controller.stop, cmd.Stop), (controller.estop, cmd.EStop)):
        late = brake()
        assert late.error == "loop_timeout" and type(host.submitted[-1]) is kind, late
        assert late.details["ticket"] == host.submitted[-1].ticket
        assert late.message.startswith("queued, not confirmed yet: the loop gave no verdict within 0.05 s (it runs "
                                       "late"), late.message
        assert "carries it out when it reaches it" in late.message and "may still" not in late.message
    other = controller.enable()
    assert other.error == "loop_timeout" and "the command may still be carried out: see status before sending it " \
        "again" in other.message, other.message


def test_an_estop_sent_from_here_but_unconfirmed_by_a_late_loop_says_it_was_sent(rig) -> None:
    """In-process the E-stop frame goes to the actuators from the caller's thread at once:
    a late loop's missing verdict does not make that uncertain, and the reply says so."""

    class SendingHost(AgedHost):
        def estop_now(self) -> bool:
            return True

    host = SendingHost(rig.controller.thread, [0.002], running=True)
    controller = Controller(host, config=ControllerConfig(command_timeout_s=0.05), nominal=rig.geometry)
    late = controller.estop()
    assert late.error == "loop_timeout" and late.message.startswith(
        "E-stop sent to the actuators; the loop's latch of it is queued, not confirmed yet"), late.message


def test_a_loop_that_stops_reporting_while_a_command_waits_is_said_to_be_silent_not_late(rig) -> None:
    """Found by a reviewer: a loop whose last report was 0.9 s old when a stop was sent
    (not yet silent) and 1.4 s when the wait ended was said to run late and to carry the
    stop out "when it reaches it": a hung loop reaches nothing."""
    controller, host = facade(rig, [0.9, 1.4], running=True, config=ControllerConfig(command_timeout_s=0.05))
    stop = controller.stop()
    assert stop.error == "loop_timeout" and type(host.submitted[-1]) is cmd.Stop, stop
    assert stop.message.startswith("queued, to be carried out if the loop runs again: the control loop has sent no "
                                   "report for 1.4 s (its process is stopped or hung)"), stop.message
