"""Shared fixtures: the nominal geometry, a seeded true platform and small simulated campaigns.

Campaigns are small (8–10 postures per leg, few planning candidates) to keep the suite fast;
the accuracy goals at full size are measured by tools/bench_calibration.py.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.kinematics.geometry import Geometry
from hexactl.calibration.campaign import CampaignDesign
from hexactl.sim.offline_campaign import OfflineCampaign, run_offline_campaign
from hexactl.sim.true_platform import true_geometry

NOMINAL_PATH = Path(__file__).resolve().parents[2] / "config" / "platform.toml"

SMALL = CampaignDesign(postures_per_leg=10, free_postures=0, candidates=300, seed=11)


@pytest.fixture(scope="session")
def nominal() -> Geometry:
    return load_geometry(NOMINAL_PATH)


@pytest.fixture(scope="session")
def true_platform(nominal: Geometry) -> Geometry:
    return true_geometry(nominal, seed=5)


@pytest.fixture(scope="session")
def leglock_campaign(nominal: Geometry, true_platform: Geometry) -> OfflineCampaign:
    """10 leg-lock postures per leg, paper noise (σ 0.25 mm per point coordinate)."""
    return run_offline_campaign(nominal, true_platform, SMALL)


@pytest.fixture(scope="session")
def noise_free_campaign(nominal: Geometry, true_platform: Geometry) -> OfflineCampaign:
    """Leg-lock and free postures with no instrument or sensor noise."""
    design = CampaignDesign(postures_per_leg=9, free_postures=12, candidates=300, seed=3,
                            sensor_sigma_mm=0.0, point_sigma_mm=0.0)
    return run_offline_campaign(nominal, true_platform, design)
