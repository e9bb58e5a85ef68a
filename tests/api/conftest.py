"""Fixtures: a service with a fake controller, per test or shared by a module; the real service, per module."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import default_config_path
from hexactl.application.service import Service, ServiceConfig
from hexactl.kinematics.geometry import Geometry
from tests.api.support import service_here, start_service


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(default_config_path())


@pytest.fixture
def service(nominal: Geometry, tmp_path: Path) -> Iterator[SimpleNamespace]:
    (tmp_path / "data").mkdir()
    running = start_service(nominal, tmp_path / "data")
    yield running
    running.close()


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data directory for a module's real service (:func:`running`)."""
    return tmp_path_factory.mktemp("data")


@pytest.fixture(scope="module")
def running(data_dir: Path) -> Iterator[Service]:
    """The whole service on its simulator (loop and API processes), one per module."""
    with service_here(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    data_dirs=(data_dir,))) as service:
        yield service


@pytest.fixture(scope="module")
def shared_service(nominal: Geometry, tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimpleNamespace]:
    """One service for a module's many requests (hypothesis examples)."""
    running = start_service(nominal, tmp_path_factory.mktemp("data"))
    yield running
    running.close()
