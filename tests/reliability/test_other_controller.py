"""Another controller on the same CAN bus (a second ``hexactl serve`` started by mistake, a
vendor tool): the actuators would follow whichever of the two commanded last. ``enable`` is
refused while one has been heard within the window, an enabled controller that hears one
latches FAULT and E-stops the actuators (holding would not hold them), and once the other has been silent for the
window, ``reset`` and ``enable`` work again. Two controllers and six firmwares on one
``memory:`` bus, stepped in simulated time: deterministic, no threads."""

from __future__ import annotations

import itertools
import math

import pytest

from firmware_proto.codec import LoopRate
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.can.transport import open_bus
from hexactl.control.config import ControllerConfig, LoopConfig
from hexactl.control.hardware import ActuatorState
from hexactl.control.local_controller import LocalController
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S
from hexactl.kinematics.geometry import Geometry
from hexactl.sim.actuator_bus import ActuatorBus, actuator_params_for, make_firmwares, zero_posture_readings_mm

RATE_HZ = 500
_channels = itertools.count()


class Bench:
    """Six simulated actuators on a ``memory:`` bus; controllers join it with :meth:`controller`."""

    def __init__(self, geometry: Geometry) -> None:
        self.channel = f"memory:other-controller-{next(_channels)}"
        self.geometry = geometry
        self.t_ns = 1_000_000_000
        self.period_ns = 1_000_000_000 // RATE_HZ
        self.actuators = ActuatorBus(open_bus(self.channel), make_firmwares(zero_posture_readings_mm(geometry),
                                                                            actuator_params_for(geometry)))
        self.controllers: list[LocalController] = []

    def clock(self) -> int:
        return self.t_ns

    def controller(self) -> LocalController:
        """A controller as ``hexactl serve`` composes one, on its own link to the bus; stepped by :meth:`run`."""
        link = CanActuatorLink(open_bus(self.channel), LinkConfig(loop_rate=LoopRate(RATE_HZ)), clock_ns=self.clock)
        controller = LocalController.in_thread(link, self.geometry, "nominal", clock_ns=self.clock,
                                               config=ControllerConfig(loop=LoopConfig(rate_hz=RATE_HZ)))
        self.controllers.append(controller)
        return controller

    def stop(self, controller: LocalController) -> None:
        """The controller's process ends: it sends nothing more."""
        self.controllers.remove(controller)
        controller.hardware.close()

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.t_ns += self.period_ns
            self.actuators.step(self.t_ns / 1e9)
            for controller in self.controllers:
                controller.step(self.t_ns)

    def run_until(self, done, seconds: float) -> None:
        for _ in range(round(seconds * RATE_HZ)):
            self.run(1)
            if done():
                return
        raise AssertionError(f"not done within {seconds} s")

    def close(self) -> None:
        for controller in self.controllers:
            controller.hardware.close()
        self.actuators.close()


@pytest.fixture
def bench(nominal: Geometry):
    bench = Bench(nominal)
    yield bench
    bench.close()


def reporting(controller: LocalController) -> bool:
    """The actuators have reported (heartbeat and feedback): enable has what it needs."""
    feedback = controller.snapshot.feedback
    return feedback is not None and all(a.heartbeat_age_s < 0.2 and not math.isnan(a.position_mm)
                                        for a in feedback.actuators)


def test_enable_is_refused_while_another_controller_runs_on_the_bus(bench: Bench) -> None:
    first, second = bench.controller(), bench.controller()  # two hexactl serve: each sends its SYNC every cycle
    bench.run_until(lambda: reporting(first) and reporting(second), seconds=1.0)
    for controller in (first, second):
        refused = controller.enable()
        assert refused.error == "other_controller", refused
        assert "another controller's SYNC was heard" in refused.message and "candump" in refused.message
        other = controller.telemetry().other_controller
        assert other is not None and other.frame == "SYNC" and other.age_s < OTHER_CONTROLLER_WINDOW_S
    bench.run(5)
    assert (first.snapshot.state.value, second.snapshot.state.value) == ("disabled", "disabled")
    assert all(a.state is ActuatorState.DISABLED for a in first.snapshot.feedback.actuators)


def test_another_controller_starting_faults_the_enabled_one_its_estop_works_and_it_recovers(bench: Bench) -> None:
    first = bench.controller()
    bench.run_until(lambda: reporting(first), seconds=1.0)
    assert first.telemetry().other_controller is None
    assert first.enable().ok
    bench.run_until(lambda: first.snapshot.state.value == "enabled"
                    and all(a.state is ActuatorState.ENABLED for a in first.snapshot.feedback.actuators), seconds=1.0)

    second = bench.controller()  # started by mistake: it sends its SYNC from its first cycle on
    bench.run(2)
    # Held set-points would not hold actuators that another controller drives too: E-stopped.
    assert first.snapshot.state.value == "estop"
    fault, estop = first.snapshot.faults
    assert fault.code == "other_controller"
    assert fault.message.startswith("another controller's SYNC was heard") and "reset and enable" in fault.message
    assert estop.code == "estop" and estop.message.startswith("other_controller: holding cannot stop"), estop
    bench.run_until(lambda: all(a.state is ActuatorState.ESTOP for a in first.snapshot.feedback.actuators)
                    and second.snapshot.state.value == "estop", seconds=0.1)
    # The second sees the actuators report the E-stop, as a hardware chain's: latched there too.
    assert second.snapshot.faults[0].message == "an actuator reports E-stop (hardware chain)"
    assert second.enable().error == "latched"
    assert first.estop().ok  # nothing holds up an E-stop the operator sends too

    bench.stop(second)
    assert first.reset().ok
    bench.run(round(0.5 * RATE_HZ))  # the actuators leave their E-stop; the other is still recent
    assert first.enable().error == "other_controller"
    bench.run(round(OTHER_CONTROLLER_WINDOW_S * RATE_HZ))
    assert first.telemetry().other_controller.age_s > OTHER_CONTROLLER_WINDOW_S
    assert first.enable().ok
    bench.run(2)
    assert first.snapshot.state.value == "enabled" and first.snapshot.faults == ()


def test_another_controller_starting_estops_a_controller_holding_in_fault(bench: Bench) -> None:
    # A FAULT holds: it still sends the held set-points, which the actuators would follow by
    # turns with the other controller's as much as an enabled loop's.
    first = bench.controller()
    bench.run_until(lambda: reporting(first), seconds=1.0)
    assert first.enable().ok
    bench.run_until(lambda: all(a.state is ActuatorState.ENABLED for a in first.snapshot.feedback.actuators),
                    seconds=1.0)
    bench.actuators.firmwares[5].inject.silent = True
    bench.run_until(lambda: first.snapshot.state.value == "fault", seconds=1.0)
    bench.actuators.firmwares[5].inject.silent = False
    bench.run(5)
    assert first.snapshot.state.value == "fault" and [f.code for f in first.snapshot.faults] == ["heartbeat_lost"]

    second = bench.controller()
    bench.run(2)
    assert first.snapshot.state.value == "estop"
    assert [f.code for f in first.snapshot.faults] == ["heartbeat_lost", "other_controller", "estop"]
    bench.run_until(lambda: all(a.state is ActuatorState.ESTOP for a in first.snapshot.feedback.actuators)
                    and second.snapshot.state.value == "estop", seconds=0.1)
