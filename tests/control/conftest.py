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


class Rig:
    """A controller on ideal actuators, stepped by hand in simulated time."""

    def __init__(self, geometry: Geometry, start_pose=(0.0,) * 6, config=None) -> None:
        from hexactl.control.config import ControllerConfig
        from hexactl.control.local_controller import LocalController
        from hexactl.kinematics.inverse import sensor_setpoints
        from hexactl.kinematics.pose import absolute_from_relative
        from hexactl.sim.ideal_actuators import IdealActuators

        self.clock = SimClock()
        self.geometry = geometry
        start = sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, start_pose))
        self.actuators = IdealActuators(start, clock_ns=self.clock, record=True)
        self.controller = LocalController.in_thread(self.actuators, geometry, "nominal", config=config or ControllerConfig(),
                                     clock_ns=self.clock)
        self.period_ns = self.controller.config.loop.period_ns

    def run(self, cycles: int = 1) -> None:
        for _ in range(cycles):
            self.controller.step(self.clock.advance(self.period_ns))

    def run_until(self, done, limit: int = 20_000) -> int:
        """Step until ``done()``; returns the cycles it took (fails beyond ``limit``)."""
        for cycle in range(1, limit + 1):
            self.run()
            if done():
                return cycle
        raise AssertionError(f"not done after {limit} cycles")

    def settle(self) -> int:
        """Step until the platform holds (no motion, no sequence)."""
        return self.run_until(lambda: self.controller.snapshot.motion.value == "holding"
                              and self.controller.snapshot.sequence is None)

    def enabled(self) -> "Rig":
        assert self.controller.enable().ok
        self.run(2)
        assert self.controller.snapshot.state.value == "enabled"
        return self

    @property
    def sent(self):
        """(N, 6) array of every set-point vector sent so far."""
        import numpy as np

        return np.array([values for _, values in self.actuators.sent]).reshape(-1, 6)

    @property
    def max_step_mm(self) -> float:
        return self.geometry.limits.leg_velocity_mm_s * self.period_ns / 1e9


    def assert_setpoints_safe(self) -> None:
        """Every set-point sent so far lies inside the stroke and within one velocity
        step of the one before."""
        import numpy as np

        sent = self.sent
        low, high = self.geometry.limits.stroke
        assert np.all(np.isfinite(sent))
        assert np.all((sent >= low) & (sent <= high))
        if len(sent) > 1:
            assert np.max(np.abs(np.diff(sent, axis=0))) <= self.max_step_mm * (1 + 1e-9)


@pytest.fixture
def make_rig(geometry):
    """Rig factory: ``make_rig(start_pose=…, config=…, geometry=…)``."""

    def make(start_pose=(0.0,) * 6, config=None, geometry=geometry) -> Rig:
        return Rig(geometry, start_pose, config)

    return make


@pytest.fixture
def rig(make_rig) -> Rig:
    return make_rig()
