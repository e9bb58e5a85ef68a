"""The controller facade with its loop in a thread of this process, which it starts,
steps by hand (tests, simulation) and stops: the lifecycle half of the ros2_control
"controller manager", apart from the commands (:class:`~hexactl.control.controller.Controller`)."""

from __future__ import annotations

import time
from collections.abc import Callable

from hexactl.control.calibration_checks import acceptance_refusal
from hexactl.control.config import ControllerConfig
from hexactl.control.controller import Controller
from hexactl.control.hardware import ActuatorInterface
from hexactl.control.host import LoopThread
from hexactl.control.planning import ActiveGeometry, Waypoint, plan_path
from hexactl.control.realtime import RealtimeReport
from hexactl.control.trajectory import KinematicState
from hexactl.kinematics.axes import RelativeMmDeg, RelativeMmRad
from hexactl.kinematics.geometry import Geometry


class LocalController(Controller):
    """:class:`~hexactl.control.controller.Controller` over :attr:`thread`, the loop of
    this process. Build it with :meth:`in_thread`."""

    def __init__(self, thread: LoopThread, *, config: ControllerConfig, nominal: Geometry,
                 ticket_start: int = 1) -> None:
        super().__init__(thread, config=config, nominal=nominal, ticket_start=ticket_start)
        self.thread = thread

    @classmethod
    def in_thread(
        cls,
        hardware: ActuatorInterface,
        geometry: Geometry,
        calibration_id: str,
        *,
        calibration_source: str = "",
        config: ControllerConfig | None = None,
        nominal: Geometry | None = None,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> LocalController:
        """The controller with its loop in this process, driving ``hardware``, on
        ``geometry`` (with its identity: the caller computes the id, e.g. a content hash).
        ``nominal`` defaults to ``geometry``. ``clock_ns``: monotonic time for
        cycles stepped by hand and for the first one, run here, so status and telemetry
        work at once and the commanded pose starts where the platform is.

        :raises ValueError: if ``geometry``'s limits differ from ``nominal``'s, or it is
            not a plausible calibration of it (the message names each parameter and bound)
        """
        nominal = nominal or geometry
        if refusal := acceptance_refusal(geometry, "the start calibration", nominal):
            raise ValueError(refusal.message)
        config = config or ControllerConfig()
        thread = LoopThread(hardware, ActiveGeometry.of(geometry, calibration_id, calibration_source), config, clock_ns)
        return cls(thread, config=config, nominal=nominal)

    @property
    def hardware(self) -> ActuatorInterface:
        """The actuators the loop drives."""
        return self.thread.hardware

    def start(self, exchange: Callable[[], None] | None = None) -> RealtimeReport:
        """Start the loop thread, with ``exchange`` for its slack (see
        :meth:`~hexactl.control.loop.ControlLoop.start`); returns what the real-time set-up obtained."""
        # Plan one small move, and discard it, before the thread freezes the heap: the
        # first plan creates lazily initialised module state (numpy, ruckig, pydantic)
        # that would otherwise fill, and lengthen, the loop's first young collection.
        s = self.snapshot
        plan_path(self._context(s), KinematicState.at_rest(RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
                  [Waypoint(RelativeMmDeg(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))])
        return self.thread.loop.start(exchange)

    def shutdown(self) -> None:
        """Stop the loop thread (the actuators keep their state: disable first)."""
        self.thread.loop.stop()

    def step(self, now_ns: int) -> None:
        """Run one cycle at monotonic ``now_ns`` (tests, simulation); not while the thread runs."""
        loop = self.thread.loop
        if loop.running:
            raise RuntimeError("the loop thread is running: it steps by itself")
        loop.step(now_ns)
