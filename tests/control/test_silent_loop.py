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
    submitted: list[cmd.Command] = field(default_factory=list)
    reports: int = 0

    @property
    def snapshot(self):
        return self.thread.snapshot

    def report(self, stats_max_age_s: float) -> LoopReport:
        self.reports += 1
        report = self.thread.report(stats_max_age_s)
        age = self.ages.pop(0) if len(self.ages) > 1 else self.ages[0]
        return replace(report, stats=replace(report.stats, report_age_s=age))

    def submit(self, command: cmd.Command) -> None:
        self.submitted.append(command)

    def estop_now(self) -> None:
        return None

    def take_recorded(self) -> list:
        return []


def facade(rig, ages: list[float]) -> tuple[Controller, AgedHost]:
    host = AgedHost(rig.controller.thread, ages)
    return Controller(host, config=ControllerConfig(), nominal=rig.geometry), host


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
