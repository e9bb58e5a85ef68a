"""A pose stream into the controller on ideal actuators, stepped in simulated time: how the
loop follows a stream with no host's timing in it (tools/bench_stream.py's tracking table,
tools/bench_cueing.py's cue as performed)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.control.config import ControllerConfig
from hexactl.control.local_controller import LocalController
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative, pose_mm_rad_to_mm_deg
from hexactl.sim.ideal_actuators import IdealActuators

START_NS = 1_000_000_000


class SimulatedStream:
    """The controller (default configuration) on ideal actuators at the zero posture of
    ``geometry`` (default: config/platform.toml), enabled, with a stream open in the zero
    frame. :meth:`send` hands it a sample as the receiver would, :meth:`step` runs one
    loop period."""

    def __init__(self, geometry: Geometry | None = None, source: str = "simulated") -> None:
        geometry = geometry or load_geometry(default_config_path())
        self.now_ns = START_NS
        self._before: tuple[Sequence[float], float] | None = None
        actuators = IdealActuators(sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, (0.0,) * 6)),
                                   clock_ns=lambda: self.now_ns)
        self.controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(),
                                                    clock_ns=lambda: self.now_ns)
        self.period_ns = self.controller.config.loop.period_ns
        assert self.controller.enable().ok
        self.step(), self.step()
        opened = self.controller.stream_open(source)
        assert opened.ok, opened.message
        self.step()

    @property
    def time_s(self) -> float:
        """Simulated time since the start, s."""
        return (self.now_ns - START_NS) / 1e9

    def send(self, pose_mm_deg: Sequence[float], sequence: int, sent_s: float) -> None:
        """A sample (relative mm and deg, numbered, stamped by its sender), arriving now,
        handed over with the one sent before it as the receiver hands it."""
        self.controller.stream_target(pose_mm_deg, sequence, sent_s, self.now_ns, self._before)
        self._before = (tuple(pose_mm_deg), sent_s)

    def step(self) -> None:
        """One loop period."""
        self.now_ns += self.period_ns
        self.controller.step(self.now_ns)

    @property
    def pose_command(self) -> list[float]:
        """The pose the loop commanded this cycle, relative mm and deg."""
        return pose_mm_rad_to_mm_deg(self.controller.snapshot.pose_command).tolist()

    @property
    def guard_clamps(self) -> int:
        return self.controller.snapshot.clamped_cycles


def perform(poses_mm_deg: Sequence[Sequence[float]], period_s: float, geometry: Geometry | None = None
            ) -> tuple[np.ndarray, int]:
    """Stream ``poses_mm_deg`` (relative mm and deg), one every ``period_s``, stamped with
    their simulated time; the pose the loop commanded at the instant of each (before the
    loop has it: the stream's lag counts), (N, 6) mm and deg, and the loop's guard clamps."""
    stream = SimulatedStream(geometry, source="performed")
    cycles_per_sample = round(period_s * 1e9 / stream.period_ns)
    commanded = []
    for sequence, pose in enumerate(poses_mm_deg):
        commanded.append(stream.pose_command)
        stream.send(pose, sequence, sequence * period_s)
        for _ in range(cycles_per_sample):
            stream.step()
    return np.array(commanded), stream.guard_clamps
