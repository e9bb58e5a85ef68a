"""The test motions are measured with the calibration their phase is about: the planned
geometry before calibration, the campaign's calibration after. Another client's load or
rollback meanwhile (before a waypoint's move, or while it is measured) is never measured
as that phase; it stopped nothing, and the errors of the other calibration went into the
before/after comparison and its verdict."""

from __future__ import annotations

import io

import numpy as np
import pytest

from hexactl.application.campaign.driver import CampaignError, PlatformDriver
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import _validate
from hexactl.application.campaign.store import VALIDATION_FILE, CampaignStore
from hexactl.calibration.campaign import CampaignDesign
from tests.campaign.test_instruments_and_store import points_at

PLANNED, OTHER = "91c81ae0fffd8fc2", "0123456789abcdef"


class Controller:
    """A controller whose moves end on their goal; another client swaps its calibration
    to OTHER just before move number ``swap_before_move``."""

    def __init__(self, swap_before_move: int | None = None) -> None:
        self.swap_before_move, self.calibration_id = swap_before_move, PLANNED
        self.pose, self.moves, self.polls = [0.0] * 6, 0, 0

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "move":
            self.moves += 1
            if self.moves == self.swap_before_move:
                self.calibration_id = OTHER
            self.pose = list(fields["pose"])  # type: ignore[call-overload]
            return {"duration": 0.0, "goal": self.pose}
        self.polls += 1
        record = {"state": "enabled", "motion": "holding", "sequence": None, "leg_feedback": [400.0] * 6,
                  "loop": {"report_age_s": 0.002},
                  "t": 0.1 * self.polls, "faults": [], "pose_command": self.pose, "events": [],
                  "calibration_id": self.calibration_id}
        return {"status": record}


class Instrument:
    """The exact feature points of the commanded pose; another client swaps the
    calibration while measurement ``swap_during`` is taken."""

    description = "exact points"

    def __init__(self, geometry, controller: Controller, swap_during: int | None = None) -> None:
        self.geometry, self.controller, self.swap_during, self.taken = geometry, controller, swap_during, []

    def measure(self, index: int, label: str) -> np.ndarray:
        self.taken.append(index)
        if index == self.swap_during:
            self.controller.calibration_id = OTHER
        return points_at(self.geometry, self.controller.pose)


@pytest.mark.parametrize(("swap_before_move", "swap_during", "measured", "said"), [
    (3, None, [0, 1], r"runs calibration 0123456789abcdef, not 91c81ae0fffd8fc2, which the test motions before "
                      r"calibration are measured with: .*Nothing was measured at x_sweep 3/9"),
    (None, 2, [0, 1, 2], r"did not hold still while it was measured .*calibration 91c81ae0fffd8fc2 → 0123456789abcdef"),
])
def test_test_motions_are_not_measured_under_another_clients_calibration(nominal, tmp_path, swap_before_move,
                                                                         swap_during, measured, said) -> None:
    controller = Controller(swap_before_move)
    instrument = Instrument(nominal, controller, swap_during)
    with CampaignStore.open(tmp_path / "c", nominal, CampaignDesign(postures_per_leg=1, candidates=50)) as store:
        with pytest.raises(CampaignError, match=said):
            _validate(PlatformDriver(controller), store, instrument, "before", PLANNED,  # type: ignore[arg-type]
                      Progress(io.StringIO(), io.StringIO()))
    assert instrument.taken == measured
    rows = [line for line in (tmp_path / "c" / VALIDATION_FILE).read_text().splitlines()
            if line.startswith("before")]
    assert len(rows) == 2  # the waypoints measured with the planned geometry, and no other


@pytest.mark.parametrize(("phase", "again"), [
    ("before", "hexactl load-calibration of the geometry file the campaign was planned with"),
    ("after", "hexactl load-calibration {directory}/calibration.toml"),
])
def test_the_way_back_names_the_calibrations_file_not_a_rollback(nominal, tmp_path, phase, again) -> None:
    """Found from outside: after another client's rollback the campaign advised
    `hexactl rollback-calibration`, which went back one more load, to an unrelated file."""
    controller = Controller(1)
    with CampaignStore.open(tmp_path / "c", nominal, CampaignDesign(postures_per_leg=1, candidates=50)) as store:
        with pytest.raises(CampaignError) as raised:
            _validate(PlatformDriver(controller), store, Instrument(nominal, controller), phase, PLANNED,  # type: ignore[arg-type]
                      Progress(io.StringIO(), io.StringIO()))
    said = str(raised.value)
    assert f"make {PLANNED} active again ({again.format(directory=(tmp_path / 'c').resolve())})" in said, said
    assert "rollback-calibration" not in said


def test_a_resumed_campaign_on_another_calibration_is_told_the_way_that_resumes_it(nominal, tmp_path) -> None:
    """Found from outside: resuming while the controller ran another calibration advised
    giving the geometry it runs (--config), which the campaign's directory then refused:
    it was planned on another."""
    from hexactl.application.campaign.runner import CampaignSettings, run_campaign

    design = CampaignDesign(postures_per_leg=1, candidates=50)
    with CampaignStore.open(tmp_path / "c", nominal, design):
        pass  # planned, nothing measured: stopped at once
    controller = Controller()
    controller.call("status")
    controller.calibration_id = OTHER
    controller.call = _with_locked_leg(controller.call)  # type: ignore[method-assign]
    controller.request = lambda cmd, **fields: {"ok": True}  # type: ignore[attr-defined]  # progress, for displays
    with pytest.raises(CampaignError) as raised:
        run_campaign(controller, nominal, Instrument(nominal, controller), CampaignSettings(tmp_path / "c", design),  # type: ignore[arg-type]
                     Progress(io.StringIO(), io.StringIO()))
    said = str(raised.value)
    assert f"runs calibration {OTHER}, not the geometry the campaign is planned on" in said, said
    assert "make it active again (hexactl load-calibration of the geometry file the campaign was planned with), then " \
           "run the same command again to resume" in said
    assert "give the geometry it runs" not in said and controller.moves == 0


def _with_locked_leg(call):
    """``call``, its status records with the field :meth:`PlatformDriver.prepare` reads."""
    def calling(cmd: str, **fields: object) -> dict:
        reply = call(cmd, **fields)
        if "status" in reply:
            reply["status"]["locked_leg"] = None
        return reply
    return calling
