from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import DEFAULT_CONFIG
from hexactl.kinematics.geometry import Geometry
from tests.kinematics.calibrations import measured

REPOSITORY = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(REPOSITORY / DEFAULT_CONFIG)


@pytest.fixture(scope="session", params=["nominal", "measured"])
def platform(request: pytest.FixtureRequest, nominal: Geometry) -> Geometry:
    """The nominal platform, then a measured one (:func:`~tests.kinematics.calibrations.measured`)."""
    return nominal if request.param == "nominal" else measured(nominal)
