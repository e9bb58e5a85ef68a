"""Fixtures of the campaign tests: the nominal geometry."""

from __future__ import annotations

import pytest

from hexactl.adapters.files.geometry_file import default_config_path, load_geometry
from hexactl.kinematics.geometry import Geometry


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(default_config_path())
