"""``hexactl campaign`` end to end against a service on the simulator (the real API,
controller, CAN link, actuator firmwares and simulated instrument, in a process of its
own), interrupted after a few postures and resumed; and its refusals before anything
moves."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator

import numpy as np
import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.application.campaign.driver import ControllerFault, PlatformDriver
from hexactl.application.campaign.instruments import ServiceInstrument
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import CampaignSettings, run_campaign
from hexactl.application.campaign.store import (
    CALIBRATION_FILE,
    MEASUREMENTS_FILE,
    PLAN_FILE,
    VALIDATION_FILE,
)
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import (
    geometry_id,
    geometry_to_toml,
    load_geometry,
)
from hexactl.adapters.files.measurements import read_measurements
from hexactl.application.service import ServiceConfig, ServiceProcess
from hexactl.calibration.campaign import CampaignDesign, achieved_pose
from hexactl.calibration.test_motions import COMPOUND, PAPER_TEST_MOTIONS
from hexactl.control.trajectory import MotionLimits
from tests.api.support import start_service

LOCAL = "tcp://127.0.0.1:*"
PER_LEG, ENVELOPE = 2, 0.6  # 12 postures, short moves: enough for `full` to beat the nominal geometry by far
RESETS = 20  # a loaded test host can stall the simulator past its actuators' watchdog
_DEFAULT = MotionLimits()
FAST = MotionLimits(max_velocity=tuple(4 * v for v in _DEFAULT.max_velocity),
                    max_acceleration=tuple(4 * v for v in _DEFAULT.max_acceleration),
                    max_jerk=tuple(8 * v for v in _DEFAULT.max_jerk))
"""Four times the default motion limits: the legs' own speed limit still holds every move."""


class InterruptAfter(Progress):
    """Ctrl-C right after the ``count``-th step of the phase whose title starts with
    ``phase`` (``postures``, ``test motions``) has been saved."""

    def __init__(self, phase: str, count: int) -> None:
        super().__init__(io.StringIO(), io.StringIO())
        self.phase, self.count = phase, count

    def step(self, done: int, label: str) -> None:
        super().step(done, label)
        if self.title.startswith(self.phase) and done == self.count:
            raise KeyboardInterrupt


@pytest.fixture(scope="module")
def service() -> Iterator[ServiceProcess]:
    """The service in a process of its own, as in use (and as the demo runs it)."""
    with ServiceProcess(ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, motion=FAST,
                                      log_level="WARNING")) as running:
        yield running


def test_interrupted_campaign_resumes_and_apply_calibrates_the_controller(service, nominal, tmp_path, capsys) -> None:
    out = tmp_path / "campaign"
    with HexactlClient(service.api_endpoint) as client, pytest.raises(KeyboardInterrupt):
        design = CampaignDesign(postures_per_leg=PER_LEG, envelope_fraction=ENVELOPE)
        settings = CampaignSettings(out, design, reset_faults=RESETS)
        run_campaign(client, nominal, ServiceInstrument(client), settings, InterruptAfter("postures", 3))
    first_rows = data_rows(out / MEASUREMENTS_FILE)
    assert len(first_rows) == 3

    status = main(["campaign", "--out", str(out), "--api", service.api_endpoint, "--per-leg", str(PER_LEG),
                   "--envelope", str(ENVELOPE), "--apply", "--reset-faults", str(RESETS), "--timeout", "30"])
    captured = capsys.readouterr()
    printed = captured.out
    assert status == 0, printed + captured.err
    assert "resuming the campaign" in printed and "3 postures and 20 test-motion waypoints already measured" in printed

    # Every planned posture exactly once, in the plan's order; the three from before the interruption kept as saved.
    saved = read_measurements(out / MEASUREMENTS_FILE, 3)
    planned = [leg for leg in range(1, 7) for _ in range(PER_LEG)]
    assert list(saved.data.locked_leg) == planned and not saved.problems
    assert data_rows(out / MEASUREMENTS_FILE)[:3] == first_rows
    for leg in range(1, 7):  # the locked leg really held
        rows = saved.data.locked_rows(leg)
        assert np.ptp(saved.data.readings_mm[rows, leg - 1]) < 0.01
    assert len((out / VALIDATION_FILE).read_text().splitlines()) == 2 + 40
    assert (out / PLAN_FILE).exists() and (out / "report" / "index.html").exists()

    # The test motions: the largest position error is down by far.
    errors = validation_errors(out / VALIDATION_FILE)
    assert errors["after"] < errors["before"] / 5, errors
    assert any(line.endswith(": improved") for line in printed.splitlines())

    # The calibration is the controller's now, and the platform goes where it is told.
    calibration = load_geometry(out / CALIBRATION_FILE)
    target = list(COMPOUND.waypoints[-1])
    with HexactlClient(service.api_endpoint) as client:
        record = client.call("status")["status"]
        assert record["calibration_id"] == geometry_id(calibration)
        # What displays (the dashboard) were told: the campaign's last words and its report.
        report = record["campaign"]["report"]
        assert report["calibration_id"] == geometry_id(calibration) and report["improved"]
        assert [motion["motion"] for motion in report["validation"]] == [motion.name for motion in PAPER_TEST_MOTIONS]
        assert max(motion["after_position_mm"] for motion in report["validation"]) == pytest.approx(errors["after"], abs=1e-6)
        zero1 = next(parameter for parameter in report["parameters"] if parameter["name"] == "zero1")
        assert zero1["value"] == pytest.approx(calibration.zero_lengths[0])
        assert zero1["sigma"] == pytest.approx(calibration.calibration.zero_lengths_std_mm[0], rel=1e-6)
        assert any("improved" in sentence for sentence in record["campaign"]["said"])
        driver = PlatformDriver(client)
        for _ in range(RESETS):
            try:
                driver.prepare()
                driver.move(target)
                break
            except ControllerFault:  # the loaded host again
                driver.reset()
        measured = achieved_pose(nominal, np.array(client.call("measure")["points"]))
    assert np.max(np.abs(measured - target)[:3]) < errors["before"] / 5


def data_rows(path) -> list[str]:
    """A CSV file's lines after its header, comments left out."""
    return [line for line in path.read_text().splitlines() if not line.startswith("#")][1:]


def validation_errors(path) -> dict[str, float]:
    """The largest |achieved − commanded| position coordinate per phase of a validation.csv, mm."""
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    errors: dict[str, float] = {}
    for row in csv.DictReader(lines):
        error = max(abs(float(row[f"achieved_{axis}"]) - float(row[f"command_{axis}"])) for axis in "xyz")
        errors[row["phase"]] = max(errors.get(row["phase"], 0.0), error)
    return errors


def test_a_bad_instrument_file_is_refused_before_anything_moves(nominal, tmp_path, capsys) -> None:
    bad = tmp_path / "tracker.csv"
    bad.write_text("p1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z\n1,2,3,4,5,6,7,8,9\n1,2,3,4,5,6,7,8,x\n")
    (tmp_path / "data").mkdir()
    fake = start_service(nominal, tmp_path / "data")
    try:
        status = main(["campaign", "--out", str(tmp_path / "c"), "--api", fake.api, "--instrument", f"csv:{bad}"])
    finally:
        fake.close()
    assert status == 2
    assert f"{bad}: line 3: p3_z 'x' is not a number" in capsys.readouterr().err
    assert fake.controller.calls == [] and not (tmp_path / "c").exists()


def test_a_controller_on_another_geometry_is_refused_before_anything_is_planned(nominal, tmp_path, capsys) -> None:
    other = tmp_path / "other.toml"
    other.write_text(geometry_to_toml(nominal.model_copy(update={"name": "other", "zero_lengths": (1751.0,) * 6})))
    (tmp_path / "data").mkdir()
    fake = start_service(nominal, tmp_path / "data")
    try:
        status = main(["campaign", "--config", str(other), "--out", str(tmp_path / "c"), "--api", fake.api])
    finally:
        fake.close()
    assert status == 1
    assert "not the geometry the campaign is planned on ('other')" in capsys.readouterr().err
    assert fake.controller.calls == [] and not (tmp_path / "c").exists()
