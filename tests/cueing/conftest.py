from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.files.cueing_file import load_vehicle_trajectory
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.cueing.washout import VehicleTrajectory
from hexactl.kinematics.geometry import Geometry

REPOSITORY = Path(__file__).resolve().parents[2]
MANOEUVRES = ("braking", "lane_change")


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(REPOSITORY / "config" / "platform.toml")


@pytest.fixture(scope="session")
def vehicles() -> dict[str, VehicleTrajectory]:
    """The shipped manoeuvres by name."""
    return {name: load_vehicle_trajectory(REPOSITORY / "config" / "vehicles" / f"{name}.csv") for name in MANOEUVRES}
