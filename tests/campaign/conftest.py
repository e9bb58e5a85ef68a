"""Fixtures of the campaign tests: the nominal geometry."""

from __future__ import annotations

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import default_config_path
from hexactl.kinematics.geometry import Geometry


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(default_config_path())
