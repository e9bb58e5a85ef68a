"""A controller link and six simulated actuators on one in-process ``virtual:`` bus, stepped
in simulated time: deterministic, no threads, no wall clock."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from firmware_proto.codec import LoopRate
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.can.transport import open_bus
from hexactl.control.hardware import FeedbackSnapshot
from hexactl.sim.actuator_bus import ActuatorBus, make_firmwares
from hexactl.sim.actuator_firmware import ActuatorParams

START_MM = (300.0, 310.0, 320.0, 330.0, 340.0, 350.0)
PARAMS = ActuatorParams(soft_limits_um=(0, 850_000), max_velocity_um_s=400_000.0)
_channels = itertools.count()


class SimClock:
    """Simulated monotonic time for the link, in ns."""

    def __init__(self) -> None:
        self.t_ns = 0

    def __call__(self) -> int:
        return self.t_ns

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9


class Rig:
    """Link + six firmwares. Each :meth:`cycle` is one loop period: the link sends (if
    ``setpoints_mm`` is given), the actuators run to the end of the period, the link reads."""

    def __init__(self, config: LinkConfig = LinkConfig(), positions_mm: Sequence[float] = START_MM) -> None:
        channel = f"virtual:hexactl-test-{next(_channels)}"
        self.clock = SimClock()
        self.config = config
        self.period_ns = 1_000_000_000 // int(config.loop_rate)
        self.link = CanActuatorLink(open_bus(channel), config, clock_ns=self.clock)
        self.firmwares = make_firmwares(positions_mm, PARAMS)
        self.sim = ActuatorBus(open_bus(channel), self.firmwares)
        self.spy = open_bus(channel)  # a bus analyser: sees every frame, sends only when a test injects
        self.counter = 0
        self.snapshot = self.idle(0)

    @property
    def loop_rate(self) -> LoopRate:
        return self.config.loop_rate

    def close(self) -> None:
        self.link.close()
        self.sim.close()
        self.spy.shutdown()

    def cycle(self, setpoints_mm: Sequence[float] | None = None) -> FeedbackSnapshot:
        if setpoints_mm is not None:
            self.link.send_setpoints(self.counter, setpoints_mm)
            self.counter += 1
        self.clock.t_ns += self.period_ns
        self.sim.step(self.clock.t_s)
        self.snapshot = self.link.read_feedback()
        return self.snapshot

    def idle(self, cycles: int) -> FeedbackSnapshot:
        """Run ``cycles`` periods without sending set-points (cycle 0: just exchange what is pending)."""
        self.sim.step(self.clock.t_s)
        self.snapshot = self.link.read_feedback()
        for _ in range(cycles):
            self.cycle()
        return self.snapshot

    def flush(self) -> None:
        """Let the actuators handle what is on the bus now (e.g. the link's bare SYNC)."""
        self.sim.step(self.clock.t_s)

    def hold(self, cycles: int) -> FeedbackSnapshot:
        """Stream the present measured positions (what a loop does before it moves)."""
        for _ in range(cycles):
            self.cycle(self.snapshot.positions_mm)
        return self.snapshot

    def spy_frames(self) -> list[tuple[int, bytes]]:
        frames = []
        while (message := self.spy.recv(0.0)) is not None:
            frames.append((message.arbitration_id, bytes(message.data)))
        return frames
