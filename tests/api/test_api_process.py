"""``hexactl serve`` is two processes: if its API process dies, the service brings the
platform to rest, disables the actuators and exits with status 1; so does a service in a
process of its own (``ServiceProcess``, as ``hexactl demo`` runs it)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.application.service import ServiceConfig, ServiceProcess
from tools.serving import serve, spawned_children
from tests.api.test_service import WAIT_S, wait_for
from tests.reliability.support import enable


def test_the_service_stops_safely_when_its_api_process_dies(tmp_path: Path) -> None:
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=WAIT_S) as client:
            enable(client)
            client.call("move", pose=[0, 0, 30, 0, 0, 0], duration=5.0)  # under way when the API dies
        (api_pid,) = wait_for(lambda: spawned_children(served.process.pid), "the API process")
        os.kill(api_pid, signal.SIGKILL)
        assert served.wait(WAIT_S) == 1, served.log
    text = served.log
    for expected in ("the API process died (exit status -9): shutting down", "actuators disabled", "stopped"):
        assert expected in text, text
    assert "E-stop" not in text, text  # braked and disabled, not E-stopped


def test_a_service_in_a_process_of_its_own_stops_safely_when_its_api_process_dies(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    local = "tcp://127.0.0.1:*"
    config = ServiceConfig(api_endpoint=local, telemetry_endpoint=local, log_level="INFO",
                           frames_path=tmp_path / "frames.toml", kept_calibration_path=tmp_path / "kept.toml")
    with ServiceProcess(config) as service:
        with HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
            enable(client)
            client.call("move", pose=[0, 0, 30, 0, 0, 0], duration=5.0)  # under way when the API dies
        (api_pid,) = wait_for(lambda: spawned_children(service.pid), "the API process")
        os.kill(api_pid, signal.SIGKILL)
        wait_for(lambda: service.exitcode is not None, "the service to end")
        assert service.exitcode == 1
    text = capfd.readouterr().err
    for expected in ("the API process died (exit status -9): shutting down", "actuators disabled", "stopped"):
        assert expected in text, text
    assert "E-stop" not in text, text
