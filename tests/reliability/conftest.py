"""Fixtures of the reliability suite: a real service on the simulator, watched by an
independent bus monitor that fails any test during which a set-point broke the limits."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.can.bus_monitor import MONITOR_THREAD_NAME, BusMonitor
from hexactl.application.service import Service, ServiceConfig
from hexactl.kinematics.geometry import Geometry
from tests.api.conftest import nominal  # noqa: F401 - the session's nominal geometry, shared
from tests.api.support import below_the_loop, service_here
from tests.api.test_service import WAIT_S
from tests.reliability.support import LOCAL, RATE_HZ


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("data")


@pytest.fixture(scope="module")
def service(data_dir: Path) -> Iterator[Service]:
    """The whole service on its simulator, one per module (tests leave it recovered)."""
    with service_here(ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, data_dirs=(data_dir,),
                                    rate_hz=RATE_HZ)) as running:
        yield running


@pytest.fixture(scope="module")
def module_monitor(service: Service, nominal: Geometry) -> Iterator[BusMonitor]:  # noqa: F811
    with BusMonitor(service.simulator.bus_spec, nominal, RATE_HZ) as monitor:
        below_the_loop(service, {MONITOR_THREAD_NAME})  # it decodes every frame holding the loop's GIL (service_here)
        yield monitor


@pytest.fixture
def monitor(module_monitor: BusMonitor) -> Iterator[BusMonitor]:
    """The module's bus monitor; at the end of the test, every frame sent during it must
    have been within the limits."""
    before = len(module_monitor.violations)
    yield module_monitor
    module_monitor.catch_up()
    assert module_monitor.violations[before:] == []


@pytest.fixture
def client(service: Service, monitor: BusMonitor) -> Iterator[HexactlClient]:
    """A client of the monitored service."""
    with HexactlClient(service.api_endpoint, timeout_s=WAIT_S) as client:
        yield client
