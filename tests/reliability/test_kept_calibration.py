"""The calibration in force survives a restart of the service: kept after each load and
rollback, and with ``--calibration``; restored at start; forgotten once the nominal
geometry is back; a kept file that cannot be used refuses the start, saying what to do.
What is kept follows what the loop has in force, not the replies: a swap the loop carried
out after the reply said ``loop_timeout`` is kept too; a file that cannot be written is
reported once, and kept once it can be."""

from __future__ import annotations

import errno
import logging
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.messages import LoadCalibrationRequest, RollbackCalibrationRequest
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError
from hexactl.adapters.files import kept_calibration
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.adapters.files.kept_calibration import (CalibrationKeeper, KeptCalibration, KeptCalibrationError,
                                                   restore_calibration)
from hexactl.application.service import Service, ServiceConfig, ServiceError
from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.controller import Controller
from hexactl.control.core import CoreSnapshot
from hexactl.control.host import LoopReport, LoopThread
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.sim.ideal_actuators import IdealActuators
from tests.api.test_service import WAIT_S, status, wait_for
from tests.control.conftest import SimClock
from tests.reliability.support import LOCAL

NOMINAL = load_geometry(default_config_path())
CALIBRATED = NOMINAL.model_copy(update={"name": "calibrated", "zero_lengths": (1750.5,) * 6})


def _service(kept: Path, data_dir: Path, calibration: Path | None = None) -> Service:
    return Service.start(ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, data_dirs=(data_dir,),
                                       calibration_path=calibration, kept_calibration_path=kept, log_level="WARNING"))


def _calibration_in_force(service: Service) -> tuple[str, str]:
    with HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
        geometry = client.call("geometry")
        assert status(client)["calibration_id"] == geometry["calibration_id"]
        return geometry["calibration_id"], geometry["source"]


def test_a_calibration_loaded_live_is_kept_across_a_restart_until_the_nominal_geometry_is_back(tmp_path: Path) -> None:
    calibration = tmp_path / "cal.toml"
    calibration.write_text(geometry_to_toml(CALIBRATED))
    kept = tmp_path / "kept" / "active_calibration.toml"
    kept.parent.mkdir()
    first = _service(kept, tmp_path)
    try:
        assert not kept.exists()  # started on the nominal geometry: nothing to keep
        with HexactlClient(first.api_endpoint, timeout_s=WAIT_S) as client:
            loaded = client.call("load_calibration", path="cal.toml")
            assert loaded["message"].endswith(f"; kept for a restart in {kept}"), loaded
            assert load_geometry(kept) == CALIBRATED
            rolled_back = client.call("rollback_calibration")
            assert rolled_back["message"].endswith("no calibration kept for a restart"), rolled_back
            assert not kept.exists()
            client.call("load_calibration", path="cal.toml")
    finally:
        first.close()

    again = _service(kept, tmp_path)
    try:
        assert _calibration_in_force(again) == (geometry_id(CALIBRATED), str(calibration))
        with HexactlClient(again.api_endpoint, timeout_s=WAIT_S) as client:  # the nominal geometry, loaded: forgotten
            back = client.call("load_calibration", toml=geometry_to_toml(NOMINAL), source="nominal")
            assert back["calibration_id"] == geometry_id(NOMINAL) and not kept.exists()
    finally:
        again.close()
    nominal = _service(kept, tmp_path)
    try:
        assert _calibration_in_force(nominal)[0] == geometry_id(NOMINAL)
    finally:
        nominal.close()


def test_calibration_at_start_is_kept_and_a_kept_file_that_cannot_be_used_refuses_the_start(tmp_path: Path) -> None:
    calibration = tmp_path / "cal.toml"
    calibration.write_text(geometry_to_toml(CALIBRATED))
    kept = tmp_path / "active_calibration.toml"
    started = _service(kept, tmp_path, calibration=calibration)
    started.close()
    assert kept.read_text().startswith(f"# the calibration hexactl serve had in force (id {geometry_id(CALIBRATED)}), "
                                       f"kept for its restart; loaded from {calibration}\n")
    restored = _service(kept, tmp_path)
    try:
        assert _calibration_in_force(restored) == (geometry_id(CALIBRATED), str(calibration))
    finally:
        restored.close()

    kept.write_text(kept.read_text().replace("stroke = [0.0, 850.0]", "stroke = [0.0, 900.0]", 1))  # not the hardware's
    with pytest.raises(ServiceError, match=r"(?s)active_calibration.toml.*keeps the calibration in force when the "
                                           r"service last ran: give --calibration FILE, or remove the file"):
        _service(kept, tmp_path)
    kept.write_text("zero_lengths = [1750.0]\n")
    with pytest.raises(ServiceError, match=r"(?s)active_calibration.toml.*or remove the file to start on the nominal"):
        _service(kept, tmp_path)
    again = _service(kept, tmp_path, calibration=calibration)  # --calibration chooses, and is kept
    again.close()
    assert load_geometry(kept) == CALIBRATED


def test_a_kept_file_the_service_did_not_leave_refuses_the_start_saying_how(tmp_path: Path) -> None:
    """Found from outside: a calibration copied over the kept file while the service was
    stopped (or written there by ``calibrate -o … --force``) was restored at the next start
    as the one "kept", said in an INFO line only: a calibration never loaded through the service."""
    kept = KeptCalibration(tmp_path / "active_calibration.toml", geometry_id(NOMINAL))
    kept.keep(CALIBRATED, geometry_id(CALIBRATED), "cal.toml")
    assert restore_calibration(kept.path) == (CALIBRATED, "cal.toml")
    header, _, body = kept.path.read_text().partition("\n")
    other = CALIBRATED.model_copy(update={"zero_lengths": (1750.8,) * 6})
    kept.path.write_text(f"{header}\n{geometry_to_toml(other)}")  # edited under the header
    with pytest.raises(KeptCalibrationError, match=f"holds calibration {geometry_id(other)}, not "
                                                   f"{geometry_id(CALIBRATED)}, the one the service kept there"):
        restore_calibration(kept.path)
    kept.path.write_text(geometry_to_toml(other))  # copied there
    with pytest.raises(ServiceError, match=r"(?s)not a calibration the service kept .* never loaded through the "
                                           r"service\n.*give --calibration FILE, or remove the file"):
        _service(kept.path, tmp_path)
    # as services before the id wrote it: still restored
    kept.path.write_text(f"# the calibration hexactl serve had in force, kept for its restart; loaded from cal.toml\n{body}")
    assert restore_calibration(kept.path) == (CALIBRATED, "cal.toml")


def test_a_second_service_on_the_same_kept_files_is_refused_before_it_changes_them(tmp_path: Path) -> None:
    """A second ``hexactl serve`` started in the same working directory (other ports, or the
    same by mistake) used to take over the files the first keeps for its restart: it kept
    its own calibration there, or removed the first one's, and the first restarted on the
    wrong calibration."""
    calibration = tmp_path / "cal.toml"
    calibration.write_text(geometry_to_toml(CALIBRATED))
    kept = tmp_path / "active_calibration.toml"
    kept.with_name(".active_calibration.toml.lock").write_text("999999\n")  # left by a process long gone: no matter
    first = _service(kept, tmp_path, calibration=calibration)
    try:
        kept_text = kept.read_text()
        with pytest.raises(ServiceError, match=rf"{kept}: another hexactl serve \(process {os.getpid()}\) keeps the "
                                               r"calibration in force there for its restart: stop that service first"):
            _service(kept, tmp_path)
        with pytest.raises(ServiceError, match=r"frames.toml: another hexactl serve .* keeps the operator's frames"):
            _service(tmp_path / "elsewhere.toml", tmp_path)  # the same ./frames.toml
        assert kept.read_text() == kept_text
        assert not (tmp_path / "elsewhere.toml").exists()
    finally:
        first.close()
    _service(kept, tmp_path).close()  # once the first has stopped


def test_a_calibration_changed_by_another_client_of_the_loop_is_kept_all_the_same(tmp_path: Path) -> None:
    """The service's own facade, in the loop's process, swaps calibrations: no reply of the
    API's says so, and its process keeps them from its telemetry."""
    kept = tmp_path / "active_calibration.toml"
    service = _service(kept, tmp_path)
    try:
        loaded = service.controller.load_calibration(CALIBRATED, geometry_id(CALIBRATED), "the service's own")
        assert loaded.ok or loaded.error == "loop_timeout", loaded  # a busy host: carried out all the same
        wait_for(lambda: kept.exists() and load_geometry(kept) == CALIBRATED, "the calibration kept")
        rolled_back = service.controller.rollback_calibration()
        assert rolled_back.ok or rolled_back.error == "loop_timeout", rolled_back
        wait_for(lambda: not kept.exists(), "the nominal geometry back, nothing kept")
    finally:
        service.close()


# -- what is kept follows the loop, not the replies (in this process, the loop stepped by hand) --

LATE = ControllerConfig(command_timeout_s=0.01)
"""The facade waits this little for a verdict: the test's loop gives none before it is stepped."""


class LateLoop:
    """A loop that says it runs by itself, so the facade waits for its verdicts, but that
    only the test steps: each command is answered ``loop_timeout`` and carried out when
    the test steps the loop, as on a busy host whose loop came late."""

    def __init__(self, nominal) -> None:
        start = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, (0.0,) * 6))
        self.clock = SimClock()
        self.thread = LoopThread(IdealActuators(start, clock_ns=self.clock),
                                 ActiveGeometry.of(nominal, geometry_id(nominal), "nominal.toml"), LATE,
                                 clock_ns=self.clock)

    @property
    def snapshot(self) -> CoreSnapshot:
        return self.thread.snapshot

    def report(self, stats_max_age_s: float) -> LoopReport:
        return replace(self.thread.report(stats_max_age_s), running=True)

    def submit(self, command: cmd.Command) -> None:
        self.thread.submit(command)

    def estop_now(self) -> bool:
        return self.thread.estop_now()

    def take_recorded(self) -> list:
        return self.thread.take_recorded()

    def step_until(self, done: Callable[[], bool], limit: int = 100) -> None:
        for _ in range(limit):
            self.thread.loop.step(self.clock.advance(self.thread.loop.period_ns))
            if done():
                return
        raise AssertionError(f"not done after {limit} cycles")


class Seconds:
    """Monotonic seconds under the test's control (the keeper's retry interval)."""

    now = 100.0

    def __call__(self) -> float:
        return self.now


def _late_handler(tmp_path: Path, kept: Path, clock: Seconds | None = None) -> tuple[CommandHandler, LateLoop]:
    (tmp_path / "cal.toml").write_text(geometry_to_toml(CALIBRATED))
    loop = LateLoop(NOMINAL)
    controller = Controller(loop, config=LATE, nominal=NOMINAL)
    keeper = CalibrationKeeper(KeptCalibration(kept, geometry_id(NOMINAL)), controller.active_geometry,
                               clock=clock or Seconds())
    return CommandHandler(controller, DataDirectories([tmp_path]), keeper=keeper), loop


LOAD = LoadCalibrationRequest(v=1, id=1, cmd="load_calibration", path="cal.toml")
ROLLBACK = RollbackCalibrationRequest(v=1, id=2, cmd="rollback_calibration")


def _in_force(loop: LateLoop, calibration: str) -> Callable[[], bool]:
    return lambda: loop.snapshot.active.calibration_id == calibration


def test_a_calibration_the_loop_swaps_in_after_a_loop_timeout_is_kept_and_forgotten_the_same_way(tmp_path: Path) -> None:
    kept = tmp_path / "active_calibration.toml"
    handler, loop = _late_handler(tmp_path, kept)
    with pytest.raises(ApiError) as late:
        handler(LOAD)
    assert late.value.code == "loop_timeout", late.value.message
    loop.step_until(_in_force(loop, geometry_id(CALIBRATED)))  # the loop carries it out all the same
    handler.record()  # as the telemetry publisher does each period
    assert load_geometry(kept) == CALIBRATED
    assert kept.read_text().startswith(f"# the calibration hexactl serve had in force (id {geometry_id(CALIBRATED)}), "
                                       f"kept for its restart; loaded from {tmp_path / 'cal.toml'}\n")

    with pytest.raises(ApiError) as late:
        handler(ROLLBACK)
    assert late.value.code == "loop_timeout", late.value.message
    loop.step_until(_in_force(loop, geometry_id(NOMINAL)))
    handler.record()
    assert not kept.exists()  # the nominal geometry is back in force: nothing kept


def _logged(caplog: pytest.LogCaptureFixture) -> list[tuple[int, str]]:
    """What the keeper logged: (level, message)."""
    return [(record.levelno, record.getMessage()) for record in caplog.records if record.name == kept_calibration.__name__]


def test_a_calibration_that_cannot_be_kept_is_reported_once_and_kept_once_it_can_be(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    kept = blocker / "active_calibration.toml"
    clock = Seconds()
    handler, loop = _late_handler(tmp_path, kept, clock)
    caplog.set_level(logging.INFO, logger=kept_calibration.__name__)
    with pytest.raises(ApiError):
        handler(LOAD)
    loop.step_until(_in_force(loop, geometry_id(CALIBRATED)))
    for _ in range(50):  # a second of telemetry
        handler.record()
    said = _logged(caplog)
    assert [level for level, _ in said] == [logging.WARNING], said
    assert f"calibration {geometry_id(CALIBRATED)} NOT kept for a restart ({kept}: " in said[0][1], said

    again = handler(LOAD)  # already in force: the reply says it is not kept (tried again), not the log again
    assert "NOT kept for a restart" in again["message"], again
    assert len(_logged(caplog)) == 1

    blocker.unlink()
    handler.record()
    assert not kept.exists()  # not tried again on every record
    clock.now += kept_calibration.RETRY_INTERVAL_S
    handler.record()
    assert load_geometry(kept) == CALIBRATED
    assert _logged(caplog)[1:] == [(logging.INFO, f"calibration {geometry_id(CALIBRATED)}: kept for a restart in {kept}")]
    assert handler(LOAD)["message"].endswith(f"; kept for a restart in {kept}")


def test_the_nominal_geometry_on_a_read_only_file_system_keeps_nothing_without_a_warning(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A service started in a read-only working directory on the nominal geometry warned
    "calibration … NOT kept for a restart": removing the kept file that is not there failed."""
    kept = KeptCalibration(tmp_path / "active_calibration.toml", geometry_id(NOMINAL))

    def read_only(path: object, *arguments: object, **options: object) -> None:
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))

    monkeypatch.setattr(os, "unlink", read_only)
    assert kept.keep(NOMINAL, geometry_id(NOMINAL), "nominal").startswith("the nominal geometry is in force")
    kept.path.write_text(geometry_to_toml(CALIBRATED))  # one kept before: that it stays is worth a warning
    with pytest.raises(OSError):
        kept.keep(NOMINAL, geometry_id(NOMINAL), "nominal")


def test_a_kept_calibration_changed_under_the_service_is_kept_aside_not_overwritten(tmp_path: Path) -> None:
    """The service reads its kept calibration at start only: a hand edit (or a file copied
    over it) is not in force, and the next change must not destroy it."""
    kept = tmp_path / "active_calibration.toml"
    handler, loop = _late_handler(tmp_path, kept)
    with pytest.raises(ApiError):
        handler(LOAD)
    loop.step_until(_in_force(loop, geometry_id(CALIBRATED)))
    handler.record()
    assert load_geometry(kept) == CALIBRATED
    kept.write_text(geometry_to_toml(CALIBRATED.model_copy(
        update={"zero_lengths": tuple(length + 0.5 for length in CALIBRATED.zero_lengths)})))
    edited = kept.read_text()
    with pytest.raises(ApiError):
        handler(ROLLBACK)
    loop.step_until(_in_force(loop, geometry_id(NOMINAL)))
    handler.record()
    assert not kept.exists()
    [aside] = sorted(tmp_path.glob("active_calibration.toml.changed-*"))
    assert aside.read_text() == edited


def test_a_kept_calibration_the_service_wrote_is_replaced_without_a_copy(tmp_path: Path) -> None:
    kept = KeptCalibration(tmp_path / "active_calibration.toml", geometry_id(NOMINAL))
    kept.keep(CALIBRATED, geometry_id(CALIBRATED), "cal.toml")
    said = kept.keep(NOMINAL, geometry_id(NOMINAL), "nominal", geometry_id(CALIBRATED))
    assert "changed since" not in said and sorted(tmp_path.iterdir()) == []


def test_a_calibration_refused_at_start_is_never_logged_as_active(tmp_path: Path, caplog) -> None:
    """Found from outside: ``serve --calibration`` logged "active calibration … from FILE",
    then refused it: a reader of the log took it for the one in force."""
    moved = tmp_path / "moved.toml"
    moved.write_text(geometry_to_toml(CALIBRATED.model_copy(update={"home": (0.0, 0.0, 2020.0, 0.0, 0.0, 0.0)})))
    caplog.set_level(logging.INFO, logger="hexactl.service")
    with pytest.raises(ServiceError):
        Service.start(ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, data_dirs=(tmp_path,),
                                    calibration_path=moved, kept_calibration_path=tmp_path / "kept.toml"))
    said = [record.getMessage() for record in caplog.records if record.name == "hexactl.service"]
    assert any(f"read from {moved}" in line for line in said), said
    assert not any(line.startswith("active calibration") for line in said), said


def test_a_service_started_on_a_calibration_logs_what_its_identification_warned_of(tmp_path: Path, caplog) -> None:
    """Found from outside: a calibration written "weakly determined" was taken without a word."""
    from hexactl.kinematics.geometry import CalibrationInfo

    warned = "weakly determined: the worst combination 0.66·B4.z −0.66·zero4 is known to ±70.6 mm"
    info = CalibrationInfo(method="full", created="now", input_sha256="0" * 64, postures=8, residual_rms_mm=0.1,
                           status="weakly determined", warnings=(warned,))
    weak = CALIBRATED.model_copy(update={"calibration": info})
    path = tmp_path / "weak.toml"
    path.write_text(geometry_to_toml(weak))
    caplog.set_level(logging.INFO, logger="hexactl.service")
    service = _service(tmp_path / "kept.toml", tmp_path, path)
    try:
        assert _calibration_in_force(service)[0] == geometry_id(weak)
    finally:
        service.close()
    said = [(record.levelno, record.getMessage()) for record in caplog.records if record.name == "hexactl.service"]
    assert (logging.WARNING, f"calibration {geometry_id(weak)}, when identified: {warned}") in said, said
