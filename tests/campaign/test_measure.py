"""The service's simulated instrument: ``measure`` sees the simulator's true platform."""

from __future__ import annotations

import numpy as np

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.messages import MeasureReply
from hexactl.application.service import Service, ServiceConfig
from hexactl.kinematics.rotation import rotation_matrix

LOCAL = "tcp://127.0.0.1:*"


def first_measurement(seed: int, sigma: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(measured points, the true platform's exact points) of a fresh service's first ``measure``."""
    service = Service.start(ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, simulator_seed=seed,
                                          point_sigma_mm=sigma, log_level="WARNING"))
    try:
        with HexactlClient(service.api_endpoint) as client:
            reply = client.call("measure")
        MeasureReply.model_validate(reply)
        assert service.simulator is not None
        simulator = service.simulator.measurement
        pose = simulator.platform.true_pose().absolute  # at rest: the actuators hold still while disabled
        model = np.array(simulator.instrument.feature_points_mm)
        exact = model @ rotation_matrix(*pose[3:]).T + np.array(pose[:3])
        return np.array(reply["points"]), exact
    finally:
        service.close()


def test_measure_sees_the_true_platform_with_seeded_noise(nominal) -> None:
    measured, exact = first_measurement(seed=3, sigma=None)
    assert measured.shape == (len(nominal.measurement.feature_points), 3)
    error = measured - exact
    assert 0 < np.max(np.abs(error)) < 5 * nominal.measurement.point_sigma_mm  # noise of the geometry's σ
    again, _ = first_measurement(seed=3, sigma=None)
    np.testing.assert_array_equal(again, measured)  # seeded: a run repeats exactly


def test_noise_free_instrument(nominal) -> None:
    measured, exact = first_measurement(seed=3, sigma=0.0)
    np.testing.assert_allclose(measured, exact, atol=1e-9)
