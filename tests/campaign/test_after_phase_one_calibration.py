"""The test motions after calibration judge one calibration: each waypoint's row records
the calibration it was measured with, and a resumed campaign measures again the waypoints
a stopped run measured with another one (identified from other data since), or with none
recorded (a validation.csv of an older hexactl), saying so."""

from __future__ import annotations

import io

import pytest

from hexactl.application.campaign.driver import PlatformDriver
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import _measure_after
from hexactl.application.campaign.store import VALIDATION_FILE, VALIDATION_STEPS, CampaignStore
from hexactl.calibration.campaign import CampaignDesign
from tests.campaign.test_calibration_changed import PLANNED, Controller
from tests.campaign.test_instruments_and_store import points_at

DESIGN = CampaignDesign(postures_per_leg=1, candidates=50)
A, B = "aaaaaaaaaaaaaaaa", "bbbbbbbbbbbbbbbb"


class Loading(Controller):
    """The fake controller, which locks legs (``calls``: every command) and whose
    ``load_calibration`` makes the text it is given (here the calibration's id) the
    active calibration."""

    def __init__(self) -> None:
        super().__init__()
        self.locked_leg: int | None = None
        self.calls: list[str] = []
        self.sources: list[object] = []  # what each load_calibration said it loads

    def call(self, cmd: str, **fields: object) -> dict:
        self.calls.append(cmd)
        if cmd == "load_calibration":
            self.calibration_id = str(fields["toml"])
            self.sources.append(fields.get("source"))
        elif cmd in ("leg_lock", "leg_unlock"):
            self.locked_leg = fields.get("leg")  # type: ignore[assignment]
        reply = super().call(cmd, **fields)
        if "status" in reply:
            reply["status"].update(locked_leg=self.locked_leg, leg_setpoints=[400.0] * 6)
        return reply


class Instrument:
    """The exact points of the commanded pose; Ctrl-C when measurement ``stop_at`` is due."""

    description = "exact points"

    def __init__(self, geometry, controller: Controller, stop_at: int | None = None) -> None:
        self.geometry, self.controller, self.stop_at, self.taken = geometry, controller, stop_at, []

    def measure(self, index: int, label: str):
        if index == self.stop_at:
            raise KeyboardInterrupt
        self.taken.append(index)
        return points_at(self.geometry, self.controller.pose)


def identified(nominal, directory) -> int:
    """A campaign in ``directory`` with the test motions before calibration and every
    posture measured: where the test motions after calibration start; returns how many
    measurements it holds."""
    with CampaignStore.open(directory, nominal, DESIGN) as store:
        for step in VALIDATION_STEPS["before"]:
            store.add_validation(step, points_at(nominal, step.pose))
        for posture in store.postures:
            store.add_posture(posture.leg, [400.0] * 6, points_at(nominal, posture.pose))
        return store.measurements_taken


def calibrations(directory, phase: str = "after") -> list[str | None]:
    """The calibration each of ``phase``'s rows in validation.csv was measured with (named
    in its first line)."""
    lines = (directory / VALIDATION_FILE).read_text().splitlines()
    named = dict(item.split("=") for item in lines[0].partition("measured with:")[2].split())
    return [named.get(phase) for line in lines if line.startswith(f"{phase},")]


def measure_after(nominal, directory, controller, calibration_id, instrument) -> str:
    said = io.StringIO()
    with CampaignStore.open(directory, nominal, DESIGN) as store:
        _measure_after(PlatformDriver(controller), store, instrument, calibration_id,  # type: ignore[arg-type]
                       calibration_id, Progress(said, io.StringIO()))
    return said.getvalue()


def test_waypoints_measured_with_an_older_calibration_are_measured_again(nominal, tmp_path) -> None:
    directory = tmp_path / "c"
    first_after = identified(nominal, directory)
    controller = Loading()
    with pytest.raises(KeyboardInterrupt):  # stopped after 6 waypoints measured with calibration A
        measure_after(nominal, directory, controller, A, Instrument(nominal, controller, first_after + 6))
    assert calibrations(directory) == [A] * 6

    # Rolled back as the stopped campaign said, and resumed with calibration B (identified
    # anew: a posture was measured again meanwhile).
    controller.calibration_id = PLANNED
    instrument = Instrument(nominal, controller)
    said = measure_after(nominal, directory, controller, B, instrument)
    assert controller.calibration_id == B
    assert controller.sources == [f"hexactl campaign: {directory / 'calibration.toml'}"] * 2  # the service records it
    assert f"6 test-motion waypoint(s) after calibration in {directory / VALIDATION_FILE} were measured with " \
           f"calibration {A}, not with {B}, the calibration they are to check: measuring them again" in said, said
    total = len(VALIDATION_STEPS["after"])
    assert instrument.taken == list(range(first_after, first_after + total))
    assert calibrations(directory) == [B] * total


def test_a_validation_file_of_an_older_hexactl_has_its_waypoints_after_calibration_measured_again(
        nominal, tmp_path) -> None:
    directory = tmp_path / "c"
    first_after = identified(nominal, directory)
    controller = Loading()
    with pytest.raises(KeyboardInterrupt):
        measure_after(nominal, directory, controller, A, Instrument(nominal, controller, first_after + 3))
    path = directory / VALIDATION_FILE  # as an older hexactl wrote it: no calibration named
    path.write_text(path.read_text().replace("measured with:", "(older hexactl)"))

    instrument = Instrument(nominal, controller)
    said = measure_after(nominal, directory, controller, A, instrument)
    assert "3 test-motion waypoint(s) after calibration" in said and "no calibration recorded" in said, said
    assert instrument.taken[0] == first_after  # the first waypoint after calibration measured again
    assert calibrations(directory, "before") == [PLANNED] * len(VALIDATION_STEPS["before"])
    assert calibrations(directory) == [A] * len(VALIDATION_STEPS["after"])
