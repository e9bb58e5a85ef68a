from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import DEFAULT_CONFIG
from hexactl.kinematics.geometry import Geometry

REPOSITORY = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(REPOSITORY / DEFAULT_CONFIG)


@pytest.fixture(scope="session")
def measured(nominal: Geometry) -> Geometry:
    """A platform as a calibration describes it: every joint a few mm off the nominal one on
    all three axes (the nominal's all lie at z = 0, where a term in z counts for nothing)
    and the sensors' gains off by up to 1e-4."""
    rng = np.random.default_rng(7)
    return Geometry.model_validate({
        **nominal.model_dump(),
        "base_joints": (np.array(nominal.base_joints) + rng.uniform(-3.0, 3.0, (6, 3))).tolist(),
        "platform_joints": (np.array(nominal.platform_joints) + rng.uniform(-3.0, 3.0, (6, 3))).tolist(),
        "sensor_scale_errors": rng.uniform(-1e-4, 1e-4, 6).tolist(),
    })


@pytest.fixture(scope="session", params=["nominal", "measured"])
def platform(request: pytest.FixtureRequest) -> Geometry:
    """The nominal platform, then the measured one."""
    return request.getfixturevalue(request.param)
