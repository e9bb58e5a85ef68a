"""How ``hexactl demo`` and ``hexactl campaign`` end when the campaign cannot go on or
Ctrl-C stops it: the reason on stderr, exit status 1 or 130, and ``campaign`` brakes the
platform on Ctrl-C and says when the controller still runs the campaign's calibration.
The campaign itself is replaced by one that stops at once."""

from __future__ import annotations

import pytest

import hexactl.application.campaign.runner as runner
import hexactl.application.demo as demo
from hexactl.adapters.api.client import ServiceUnavailable
from hexactl.application.campaign.driver import CampaignError
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import geometry_id, save_geometry
from hexactl.application.campaign.store import CALIBRATION_FILE
from tests.api.support import start_service

RESUME = "interrupted; what was measured is saved in {}: run the same command to resume"


def stopping(reason: BaseException):
    def run(*_arguments: object) -> None:
        raise reason

    return run


@pytest.mark.parametrize(("reason", "status", "said"), [
    (CampaignError("the platform did not settle"), 1, "the platform did not settle"),
    (KeyboardInterrupt(), 130, None),
])
def test_a_stopped_demo_says_why_and_how_to_resume(reason, status, said, monkeypatch, tmp_path, capsys) -> None:
    monkeypatch.setattr(demo, "run_demo", stopping(reason))
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == status
    assert capsys.readouterr().err.strip() == f"hexactl demo: {said or RESUME.format(out)}"


@pytest.mark.parametrize(("reason", "status", "said", "braked"), [
    (CampaignError("the controller refused a leg-lock move"), 1, "the controller refused a leg-lock move", False),
    (KeyboardInterrupt(), 130, None, True),
])
def test_a_stopped_campaign_says_why_and_brakes_on_ctrl_c(reason, status, said, braked, nominal, monkeypatch,
                                                          tmp_path, capsys) -> None:
    monkeypatch.setattr(runner, "run_campaign", stopping(reason))
    (tmp_path / "data").mkdir()
    fake = start_service(nominal, tmp_path / "data")
    out = tmp_path / "campaign"
    try:
        assert main(["campaign", "--out", str(out), "--api", fake.api]) == status
    finally:
        fake.close()
    assert capsys.readouterr().err.strip() == f"hexactl campaign: {said or RESUME.format(out)}"
    assert (("stop", ()) in fake.controller.calls) is braked


def test_a_campaign_whose_service_stops_answering_says_how_to_resume(nominal, monkeypatch, tmp_path, capsys) -> None:
    monkeypatch.setattr(runner, "run_campaign", stopping(ServiceUnavailable("no answer from tcp://127.0.0.1:1 within 5 s: "
                                                                           "is `hexactl serve` running there?")))
    (tmp_path / "data").mkdir()
    fake = start_service(nominal, tmp_path / "data")
    out = tmp_path / "campaign"
    try:
        assert main(["campaign", "--out", str(out), "--api", fake.api]) == 2
    finally:
        fake.close()
    assert capsys.readouterr().err.strip() == (
        "hexactl campaign: no answer from tcp://127.0.0.1:1 within 5 s: is `hexactl serve` running there? What was "
        f"measured is saved in {out}: run the same command again once the service answers to resume")


@pytest.mark.parametrize("reason", [CampaignError("the controller is in fault"), KeyboardInterrupt()])
@pytest.mark.parametrize("in_force", [True, False])
def test_a_stopped_campaign_says_when_its_calibration_stays_in_force(reason, in_force, nominal, monkeypatch, tmp_path,
                                                                     capsys) -> None:
    """Stopped in the test motions after calibration, the campaign leaves its calibration
    in force, and the service keeps it for its next start: without a word, an operator who
    never passed --apply ran on it, and restarted on it, without knowing."""
    monkeypatch.setattr(runner, "run_campaign", stopping(reason))
    out = tmp_path / "campaign"
    out.mkdir()
    written = nominal if in_force else nominal.model_copy(update={"name": "another calibration"})
    save_geometry(written, out / CALIBRATION_FILE)
    (tmp_path / "data").mkdir()
    fake = start_service(nominal, tmp_path / "data")  # it runs the nominal geometry
    try:
        main(["campaign", "--out", str(out), "--api", fake.api])
    finally:
        fake.close()
    lines = capsys.readouterr().err.strip().splitlines()
    told = [line for line in lines if "still runs the campaign's calibration" in line]
    if in_force:
        assert len(lines) == 2 and told == [lines[1]]
        assert geometry_id(nominal) in told[0] and str(out / CALIBRATION_FILE) in told[0]
        assert "rolls it back unless --apply keeps it" in told[0] and "hexactl rollback-calibration" in told[0]
    else:
        assert len(lines) == 1 and not told
