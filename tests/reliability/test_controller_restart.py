"""The controller dies mid-motion and a new one takes over the same actuators: they stop
on their own watchdogs and hold, the new controller finds them latched, and after
``reset`` it enables from where they stand, without a jump (checked by the bus monitor,
which sees the first set-point of each leg beside the position it reported)."""

from __future__ import annotations

import pytest

from firmware_proto.codec import Fault, LoopRate
from hexactl.adapters.can.bus_monitor import BusMonitor
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.files.geometry_file import geometry_id
from hexactl.application.service import SIMULATOR_SUPERVISION, SIMULATOR_WATCHDOG_CYCLES
from hexactl.application.simulator import Simulator
from hexactl.control.config import ControllerConfig, LoopConfig
from hexactl.control.local_controller import LocalController
from hexactl.control.hardware import ActuatorState
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import wait_for
from tests.reliability.support import BOOTING, RATE_HZ, tolerating_loop_stalls


def start_controller(simulator: Simulator, geometry: Geometry) -> LocalController:
    """A controller on its own link to the simulator's bus, as ``hexactl serve`` composes it
    with its simulator (the simulator's watchdog and supervision timeouts)."""
    link = CanActuatorLink.open(simulator.bus_spec, LinkConfig(loop_rate=LoopRate(RATE_HZ),
                                                               watchdog_cycles=SIMULATOR_WATCHDOG_CYCLES))
    controller = LocalController.in_thread(link, geometry, geometry_id(geometry),
                            config=ControllerConfig(loop=LoopConfig(rate_hz=RATE_HZ), supervision=SIMULATOR_SUPERVISION))
    controller.start()
    return controller


def enable(controller: LocalController) -> None:
    def attempt() -> bool:
        result = controller.enable()
        assert result.ok or result.error in (*BOOTING, "actuator_fault"), result
        return result.ok

    wait_for(attempt, "the controller to enable")


def at_rest(controller: LocalController) -> bool:
    telemetry = controller.telemetry()
    return telemetry.motion == "holding" and telemetry.sequence is None


def test_killed_mid_motion_then_restarted(nominal: Geometry) -> None:
    driving: list[LocalController] = []  # the controller expected to be in control, for the stall check
    monitors: list[BusMonitor] = []  # every attempt's: a repeated attempt never hides a violation

    def scenario() -> None:
        simulator = Simulator(nominal, seed=0)
        try:
            with BusMonitor(simulator.bus_spec, nominal, RATE_HZ) as monitor:
                monitors.append(monitor)
                kill_and_restart(simulator, nominal, driving)
                monitor.catch_up()
        finally:
            simulator.close()
        starts = monitor.starts[-6:]
        assert sorted(start.leg for start in starts) == [1, 2, 3, 4, 5, 6]
        assert all(start.jump_mm is not None and start.jump_mm <= 0.001 for start in starts), starts
        assert monitor.counts["cycles"] > RATE_HZ  # it watched both controllers drive

    try:
        tolerating_loop_stalls(scenario, lambda: driving[-1] if driving else None, cleanup=driving.clear)
    finally:
        assert [violation for monitor in monitors for violation in monitor.violations] == []


def kill_and_restart(simulator: Simulator, nominal: Geometry, driving: list[LocalController]) -> None:
    first = start_controller(simulator, nominal)
    driving.append(first)
    enable(first)
    assert first.move([0, 0, 150, 0, 0, 0], duration=1.0).ok, first.telemetry().faults
    wait_for(lambda: first.telemetry().pose_command[2] > 30.0 or first.telemetry().state != "enabled",
             "the platform under way")
    assert first.telemetry().state == "enabled", first.telemetry().faults

    # The crash: the loop thread ends between two cycles and the process's bus goes with it.
    # No stop, no DISABLE, no E-stop: the stream of set-points just ends.
    first.shutdown()
    first.hardware.close()
    last_command_z = first.telemetry().pose_command[2]
    driving.clear()

    second = start_controller(simulator, nominal)
    try:
        def stopped_by_watchdog() -> bool:
            feedback = second.snapshot.feedback
            return feedback is not None and all(
                actuator.state is ActuatorState.FAULT and actuator.fault_bits & Fault.COMM_TIMEOUT
                for actuator in feedback.actuators)

        wait_for(stopped_by_watchdog, "every actuator's watchdog")
        wait_for(lambda: all(a.velocity_mm_s == 0.0 for a in second.snapshot.feedback.actuators), "standstill")
        held = second.snapshot.feedback.positions_mm
        later = second.snapshot.t_ns + 200_000_000
        wait_for(lambda: second.snapshot.t_ns > later, "0.2 s of holding")
        assert second.snapshot.feedback.positions_mm == held  # on their brakes, not drifting
        assert second.telemetry().state == "disabled"  # a new controller starts disabled …
        assert second.enable().error == "actuator_fault"  # … and finds the actuators latched

        assert second.reset().ok
        enable(second)
        driving.append(second)
        telemetry = second.telemetry()
        assert telemetry.pose_command == pytest.approx(telemetry.pose_measured, abs=1e-3)
        assert telemetry.pose_command[2] == pytest.approx(last_command_z, abs=5.0)  # coasted a little, no more

        assert second.move([0, 0, 0, 0, 0, 0], duration=1.0).ok  # and it is in control again
        wait_for(lambda: at_rest(second), "the move home")
        assert second.disable().ok, second.telemetry().faults
    finally:
        second.shutdown()
        second.hardware.close()
