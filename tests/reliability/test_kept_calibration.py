"""The calibration in force survives a restart of the service: kept after each load and
rollback, and with ``--calibration``; restored at start; forgotten once the nominal
geometry is back; a kept file that cannot be used refuses the start, saying what to do."""

from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.application.service import Service, ServiceConfig, ServiceError
from tests.api.test_service import WAIT_S, status
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
    assert kept.read_text().startswith(f"# the calibration hexactl serve had in force, kept for its restart; loaded "
                                       f"from {calibration}\n")
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
