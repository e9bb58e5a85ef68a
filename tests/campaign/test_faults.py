"""Nothing is measured across a fault: a measurement during which the controller latched
a fault is not kept, the campaign resets the fault and measures again; and resetting is
bounded by faults in a row with no measurement between them, not by a small total."""

from __future__ import annotations

import io
import multiprocessing
import os
import signal
import time
from collections.abc import Callable

import numpy as np
import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.application.campaign.driver import MOVE_ATTEMPTS, CampaignError, ControllerFault, PlatformDriver, SettleCriteria
from hexactl.application.campaign.instruments import ServiceInstrument
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import CampaignSettings, _Resetting, run_campaign
from hexactl.application.campaign.store import VALIDATION_FILE
from hexactl.application.service import ServiceConfig, ServiceProcess
from hexactl.calibration.campaign import CampaignDesign
from tests.campaign.test_campaign import ENVELOPE, FAST, LOCAL, PER_LEG, InterruptAfter
from tools.serving import wait_until

START_TIMEOUT_S = 300.0  # seconds on an idle host, minutes on one loaded by other work

STALL_S = 0.5
"""A stall of the service's process: beyond the simulated actuators' 50 ms watchdog and the loop's 0.2 s supervision."""


class StallDuring:
    """The service's instrument, but measurement ``index`` is taken across a fault: the
    service's process is stopped for :data:`STALL_S` first (a loaded host, exaggerated),
    and the points are read once the fault has latched. Keeps every measurement it gave."""

    description = "the simulated instrument, with a stall during one measurement"

    def __init__(self, client: HexactlClient, index: int) -> None:
        self.instrument = ServiceInstrument(client)
        self.client, self.index = client, index
        self.given: list[tuple[int, np.ndarray]] = []

    def measure(self, index: int, label: str) -> np.ndarray:
        if index == self.index and not any(taken == index for taken, _ in self.given):
            [service] = [child for child in multiprocessing.active_children() if child.name == "hexactl-service"]
            os.kill(service.pid, signal.SIGSTOP)
            time.sleep(STALL_S)
            os.kill(service.pid, signal.SIGCONT)
            wait_until(lambda: self.client.call("status")["status"]["state"] == "fault",
                       f"a fault latched after a {STALL_S} s stall", 10, poll_s=0.01)
        points = self.instrument.measure(index, label)
        self.given.append((index, points))
        return points


def test_a_measurement_taken_across_a_fault_is_measured_again(nominal, tmp_path) -> None:
    out = tmp_path / "campaign"
    progress = InterruptAfter("test motions", 3)
    config = ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, motion=FAST, log_level="WARNING")
    with (ServiceProcess(config, START_TIMEOUT_S) as service,
          HexactlClient(service.api_endpoint, timeout_s=30) as client):
        instrument = StallDuring(client, index=1)
        settings = CampaignSettings(out, CampaignDesign(postures_per_leg=PER_LEG, envelope_fraction=ENVELOPE),
                                    reset_faults=5)
        with pytest.raises(KeyboardInterrupt):
            run_campaign(client, nominal, instrument, settings, progress)
    said = progress.out.getvalue()
    assert "resetting it and resuming (fault 1;" in said, said
    indices = [index for index, _ in instrument.given]
    assert indices[:3] == [0, 1, 1], indices  # the second waypoint measured again after the fault
    rows = [line for line in (out / VALIDATION_FILE).read_text().splitlines() if not line.startswith(("#", "phase"))]
    assert len(rows) == 3
    kept = np.array(rows[1].split(",")[15:], dtype=float)  # phase, motion, waypoint, 6 commanded, 6 achieved, points
    across, again = (points.ravel() for index, points in instrument.given if index == 1)
    assert np.allclose(kept, again, atol=1e-6) and not np.allclose(kept, across, atol=1e-6)


class FaultyDriver:
    """A driver whose controller faults on demand; counts resets."""

    def __init__(self) -> None:
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1


def faulting(times: int, measured: list[int], measure_between: bool) -> Callable[[], None]:
    """A campaign step that latches a fault ``times`` times (saving a measurement before
    each, if ``measure_between``), then finishes."""
    left = [times]

    def step() -> None:
        if left[0]:
            left[0] -= 1
            if measure_between:
                measured[0] += 1
            raise ControllerFault("the controller is in fault (COMM_TIMEOUT)", resettable=True)

    return step


def test_faults_are_reset_while_the_campaign_measures_and_stop_it_when_it_no_longer_does() -> None:
    measured = [0]
    driver = FaultyDriver()
    resetting = _Resetting(driver, 3, lambda: measured[0], Progress(io.StringIO(), io.StringIO()))
    resetting(faulting(50, measured, measure_between=True))  # many, each after a measurement: all recovered
    assert resetting.resets == driver.resets == 50
    resetting(faulting(2, measured, measure_between=False))  # the 50th and these two: 3 in a row, recovered
    assert resetting.resets == 52
    with pytest.raises(CampaignError, match="4 faults in a row with no measurement saved between them"):
        resetting(faulting(1, measured, measure_between=False))
    assert driver.resets == 52


def test_with_no_resets_allowed_a_fault_stops_the_campaign_for_the_operator() -> None:
    driver = FaultyDriver()
    resetting = _Resetting(driver, 0, lambda: 0, Progress(io.StringIO(), io.StringIO()))
    with pytest.raises(ControllerFault, match="reset it and enable it, then run the same command again"):
        resetting(faulting(1, [0], measure_between=False))
    assert driver.resets == 0


class LateVerdicts:
    """A client whose API answers ``code`` (``loop_timeout``, or ``expired`` for any
    command) to the first ``late`` moves or other commands (a loaded host), then carries
    them out; the platform is at rest throughout."""

    def __init__(self, late: int, code: str = "loop_timeout", silent_polls: int = 0) -> None:
        self.late, self.code, self.moves, self.others, self.polls = late, code, 0, 0, 0
        self.pose = [0.0] * 6
        self.silent_polls = silent_polls
        """Status records, from the first, that are a held-up loop's last report."""
        self.moved_after: list[int] = []
        """The status records read before each move."""

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "move":
            self.moves += 1
            self.moved_after.append(self.polls)
            if self.moves <= self.late:
                raise CommandError(self.code, "the loop gave no verdict in time; the command may still be carried out")
            self.pose = list(fields["pose"])  # type: ignore[call-overload]
            return {"duration": 0.0, "goal": self.pose}
        if cmd == "leg_lock":
            self.others += 1
            if self.others <= self.late:
                raise CommandError("expired", "its deadline passed before the loop reached it: not carried out")
            return {}
        self.polls += 1
        record = {"state": "enabled", "motion": "holding", "sequence": None, "leg_feedback": [400.0] * 6,
                  "loop": {"report_age_s": 3.0 if self.polls <= self.silent_polls else 0.002},
                  "t": 0.1 * self.polls, "faults": [], "pose_command": self.pose, "events": []}
        return {"status": record}


def test_a_move_without_a_verdict_is_sent_again_a_few_times_then_stops_the_campaign() -> None:
    client = LateVerdicts(late=MOVE_ATTEMPTS - 1)
    record = PlatformDriver(client).move([1.0, 0, 0, 0, 0, 0], settle=False)  # type: ignore[arg-type]
    assert record["motion"] == "holding" and client.moves == MOVE_ATTEMPTS
    hopeless = LateVerdicts(late=MOVE_ATTEMPTS)
    with pytest.raises(CampaignError, match="no verdict on the move .* in time, 3 times"):
        PlatformDriver(hopeless).move([1.0, 0, 0, 0, 0, 0])  # type: ignore[arg-type]
    assert hopeless.moves == MOVE_ATTEMPTS


def test_a_move_to_a_loop_held_up_past_a_second_is_sent_again_once_it_reports() -> None:
    """``loop_silent``: not sent, and the status records are the held-up loop's last
    report (at rest, here): the move is sent again only once the loop reports again."""
    client = LateVerdicts(late=1, code="loop_silent", silent_polls=4)
    assert PlatformDriver(client).move([1.0, 0, 0, 0, 0, 0], settle=False)["pose_command"][0] == 1.0  # type: ignore[arg-type]
    assert client.moves == 2 and client.moved_after[1] > client.silent_polls


def test_a_loop_that_stays_held_up_is_named_when_the_wait_for_it_ends() -> None:
    # The last report says "holding": "did not settle (motion holding, ...)" left the
    # operator looking at a platform at rest for what was wrong.
    client = LateVerdicts(late=1, code="loop_silent", silent_polls=10**9)
    with pytest.raises(CampaignError, match=r"did not settle .*: the control loop has sent no report for 3\.0 s "
                                            r"\(its process is stopped or hung; see hexactl status\)"):
        PlatformDriver(client, SettleCriteria(timeout_s=0.05)).move([1.0, 0, 0, 0, 0, 0])  # type: ignore[arg-type]
    assert client.moves == 1


def test_a_command_that_expired_unrun_is_sent_again_then_names_the_timeout() -> None:
    late = LateVerdicts(late=MOVE_ATTEMPTS - 1, code="expired")
    assert PlatformDriver(late).move([1.0, 0, 0, 0, 0, 0], settle=False)["motion"] == "holding"  # type: ignore[arg-type]
    assert late.moves == MOVE_ATTEMPTS
    assert PlatformDriver(late).lock(2)["motion"] == "holding"  # type: ignore[arg-type]
    assert late.others == MOVE_ATTEMPTS
    hopeless = LateVerdicts(late=MOVE_ATTEMPTS)
    with pytest.raises(CampaignError, match=r"refused leg_lock: .*not carried out.*raise --timeout"):
        PlatformDriver(hopeless).lock(2)  # type: ignore[arg-type]
    assert hopeless.others == MOVE_ATTEMPTS


class LateReset:
    """A controller in FAULT whose ``reset`` is answered ``loop_timeout`` (a loaded host);
    carried out a moment later when ``done`` (the state disabled from the second poll), else never."""

    def __init__(self, done: bool) -> None:
        self.done, self.polls = done, 0

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "reset":
            raise CommandError("loop_timeout", "the loop gave no verdict in time; the command may still be carried out")
        self.polls += 1
        return {"status": {"state": "disabled" if self.done and self.polls > 1 else "fault", "faults": []}}


def test_a_reset_answered_loop_timeout_is_judged_by_the_state_it_leaves() -> None:
    """Found from outside: ``campaign --reset-faults`` gave up on such a reply, though the
    reset had been carried out."""
    carried_out = LateReset(done=True)
    PlatformDriver(carried_out).reset()  # type: ignore[arg-type]
    assert carried_out.polls == 2
    with pytest.raises(CampaignError, match="the controller did not reset"):
        PlatformDriver(LateReset(done=False), SettleCriteria(timeout_s=0.05)).reset()  # type: ignore[arg-type]
