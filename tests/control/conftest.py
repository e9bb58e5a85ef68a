"""Shared fixtures of the control tests: the nominal geometry and a simulated clock."""

from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.kinematics.geometry import Geometry

CONFIG = Path(__file__).resolve().parents[2] / "config" / "platform.toml"


class SimClock:
    """Monotonic nanoseconds under the test's control."""

    def __init__(self, start_ns: int = 1_000_000_000) -> None:
        self.now_ns = start_ns

    def __call__(self) -> int:
        return self.now_ns

    def advance(self, ns: int) -> int:
        self.now_ns += ns
        return self.now_ns


@pytest.fixture(scope="session")
def geometry() -> Geometry:
    return load_geometry(CONFIG)


@pytest.fixture
def clock() -> SimClock:
    return SimClock()
