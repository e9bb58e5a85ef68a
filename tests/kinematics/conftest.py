from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import DEFAULT_CONFIG
from hexactl.kinematics.geometry import Geometry

REPOSITORY = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(REPOSITORY / DEFAULT_CONFIG)
