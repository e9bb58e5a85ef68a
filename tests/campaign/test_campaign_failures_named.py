"""A campaign that cannot go on because its directory became unwritable or the
controller refuses the move to the zero posture stops with a CampaignError (exit status
1) naming the file or the refusal, what to do and that the same command resumes; a leg
it had locked is unlocked."""

from __future__ import annotations

import io

import pytest

import hexactl.application.campaign.store as store_module
from hexactl.adapters.api.client import CommandError
from hexactl.application.campaign.driver import CampaignError, PlatformDriver
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import _measure_after, _measure_postures, _validate
from hexactl.application.campaign.store import MEASUREMENTS_FILE, VALIDATION_FILE, VALIDATION_STEPS, CampaignStore
from tests.campaign.test_after_phase_one_calibration import DESIGN, Instrument, Loading, identified
from tests.campaign.test_calibration_changed import PLANNED
from tests.campaign.test_instruments_and_store import points_at

RESUME = "run the same command again to resume"


class RefusingZero(Loading):
    """Soft limits that exclude the zero posture: a move there is refused at planning."""

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "move" and not any(fields["pose"]):  # type: ignore[call-overload]
            raise CommandError("path_violation", "the path leaves the soft limits")
        return super().call(cmd, **fields)


def unwritable(*_arguments: object, **_fields: object) -> None:
    raise PermissionError(1, "Operation not permitted")


def quiet() -> Progress:
    return Progress(io.StringIO(), io.StringIO())


def test_an_unwritable_directory_stops_the_test_motions_naming_the_file(nominal, tmp_path, monkeypatch) -> None:
    controller = Loading()
    with CampaignStore.open(tmp_path / "c", nominal, DESIGN) as store:
        monkeypatch.setattr(store_module, "write_atomic", unwritable)
        with pytest.raises(CampaignError, match=rf"cannot write {tmp_path / 'c' / VALIDATION_FILE}: Operation not "
                                                rf"permitted; write where .*chattr -i\)\. What was saved before is kept; .*{RESUME}"):
            _validate(PlatformDriver(controller), store, Instrument(nominal, controller), "before",  # type: ignore[arg-type]
                      PLANNED, quiet())


def test_an_unwritable_directory_stops_the_postures_and_unlocks_the_leg(nominal, tmp_path, monkeypatch) -> None:
    controller = Loading()
    with CampaignStore.open(tmp_path / "c", nominal, DESIGN) as store:
        monkeypatch.setattr(store_module, "write_measurements", unwritable)
        with pytest.raises(CampaignError, match=rf"cannot write {tmp_path / 'c' / MEASUREMENTS_FILE}: .*{RESUME}"):
            _measure_postures(PlatformDriver(controller), store, Instrument(nominal, controller),  # type: ignore[arg-type]
                              quiet())
    assert controller.calls.count("leg_lock") == 1 and controller.calls[-1] != "leg_lock"
    assert "leg_unlock" in controller.calls[controller.calls.index("leg_lock"):]
    assert controller.locked_leg is None


def test_a_refused_move_to_the_zero_posture_before_locking_a_leg_is_named(nominal, tmp_path) -> None:
    controller = RefusingZero()
    with CampaignStore.open(tmp_path / "c", nominal, DESIGN) as store:
        with pytest.raises(CampaignError, match=rf"refused the move to the zero posture where leg \d is to be locked: "
                                                rf"path_violation: .*soft limits.*{RESUME}"):
            _measure_postures(PlatformDriver(controller), store, Instrument(nominal, controller),  # type: ignore[arg-type]
                              quiet())
    assert "leg_lock" not in controller.calls


def test_a_refused_move_to_the_zero_posture_after_the_test_motions_is_named(nominal, tmp_path) -> None:
    directory = tmp_path / "c"
    identified(nominal, directory)
    controller = RefusingZero()
    with CampaignStore.open(directory, nominal, DESIGN) as store:
        for step in VALIDATION_STEPS["after"]:  # measured (some waypoints are the zero posture itself)
            store.add_validation(step, points_at(nominal, step.pose), "aaaaaaaaaaaaaaaa")
        controller.calibration_id = "aaaaaaaaaaaaaaaa"
        with pytest.raises(CampaignError, match=rf"refused the move to the zero posture at the end of the test motions "
                                                rf"after calibration: path_violation: .*{RESUME}"):
            _measure_after(PlatformDriver(controller), store, Instrument(nominal, controller),  # type: ignore[arg-type]
                           "aaaaaaaaaaaaaaaa", "aaaaaaaaaaaaaaaa", quiet())
