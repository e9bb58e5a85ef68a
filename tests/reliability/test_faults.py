"""Faults of the actuators and of the bus, on the whole service: each ends in the
controller's safe state (FAULT latched and explained; the set-points held, so healthy
actuators hold the platform where it was), no set-point beyond the limits reaches the
bus (the module's bus monitor), and ``reset`` then ``enable`` bring it back."""

from __future__ import annotations

import errno
from collections.abc import Callable, Iterator

import can
import pytest

from firmware_proto.codec import Fault
from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.can.link import CanActuatorLink
from hexactl.application.service import Service
from hexactl.control.hardware import ActuatorState
from tests.api.test_service import status, wait_for
from tests.reliability.support import (
    clear_injections,
    firmwares,
    recover,
    tolerating_loop_stalls,
)

MOVE_S = 2.0  # long enough that the fault always strikes mid-motion


def fault_during_motion(client: HexactlClient, inject: Callable[[], None], z_mm: float = 60.0,
                        duration_s: float = MOVE_S) -> dict:
    """Recover, start a move, ``inject`` while moving; the telemetry record once FAULT is latched."""
    recover(client)
    client.call("move", pose=[0, 0, z_mm, 0, 0, 0], duration=duration_s)
    wait_for(lambda: status(client)["motion"] == "moving", "the move to start")
    inject()
    return wait_for(lambda: (record := status(client))["state"] == "fault" and record, "the fault to latch")


def assert_held(client: HexactlClient) -> None:
    """In FAULT the loop keeps sending the set-points it sent last: nothing moves on."""
    first = status(client)
    second = wait_for(lambda: (record := status(client))["t"] > first["t"] + 0.1 and record, "later telemetry")
    assert second["state"] == "fault" and second["leg_setpoints"] == first["leg_setpoints"]
    assert second["motion"] == "holding" and second["sequence"] is None


def codes(record: dict) -> list[tuple[str, int | None]]:
    return [(fault["code"], fault["leg"]) for fault in record["faults"]]


def back_in_service(client: HexactlClient) -> None:
    """Reset, enable and move: the service recovered."""
    recover(client)
    client.call("move", pose=[0, 0, 10, 0, 0, 0], duration=0.3)
    wait_for(lambda: status(client)["motion"] == "holding", "the move to end")
    record = status(client)
    assert record["state"] == "enabled" and record["faults"] == []


@pytest.fixture
def actuators(service: Service) -> Iterator[tuple]:
    """The six firmwares, their fault injection switched off again after the test."""
    yield firmwares(service)
    clear_injections(service)


def test_lost_heartbeat(client, actuators, service) -> None:
    def scenario() -> None:
        record = fault_during_motion(client, lambda: setattr(actuators[2].inject, "silent", True))
        # The simulator's supervision gives heartbeats and applied set-points the same 0.2 s:
        # either explains a silent leg first.
        assert codes(record)[0] in (("heartbeat_lost", 3), ("setpoints_not_applied", 3))
        assert_held(client)
        assert client.request("enable")["error"]["code"] == "latched"
        actuators[2].inject.silent = False
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, {("heartbeat_lost", 3), ("setpoints_not_applied", 3)},
                           lambda: clear_injections(service))


def test_actuator_fault_stays_until_its_cause_is_gone(client, actuators, service) -> None:
    def scenario() -> None:
        record = fault_during_motion(client, lambda: setattr(actuators[4].inject, "sensor_fault", True))
        assert codes(record)[0] == ("actuator_fault", 5)
        assert record["faults"][0]["message"] == "leg 5 reports FAULT, faults: sensor (0x80)"
        assert_held(client)
        client.call("reset")  # the controller resets; the actuator refuses CLEAR_FAULT while its sensor is bad
        wait_for(lambda: status(client)["state"] == "disabled", "the reset")
        # The latched faults are cleared, but the telemetry still shows the actuator's.
        leg5 = wait_for(lambda: (legs := status(client)["legs"])[4]["state"] == "fault" and legs[4], "leg 5's state")
        assert leg5["fault_bits"] & int(Fault.SENSOR) and "sensor" in leg5["fault_names"]
        refusal = wait_for(lambda: (reply := client.request("enable"))["ok"] is False
                           and reply["error"]["code"] == "actuator_fault" and reply, "enable to be refused")
        assert refusal["error"]["message"].startswith("leg 5: FAULT, faults: sensor (0x80)")
        actuators[4].inject.sensor_fault = False
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, {("actuator_fault", 5)}, lambda: clear_injections(service))


def test_a_jammed_leg_is_a_following_error_before_the_drive_notices(client, actuators, service) -> None:
    """Leg 2's drive stops moving mid-motion: the loop latches ``following_error`` on leg 2
    once it is more than the limit from the set-point it applied, for longer than allowed;
    before that, the move went on and was reported done with the leg 19 mm off. Slow enough
    (about 15 mm/s a leg) that the drive's own 25 mm limit comes well after the loop's."""
    supervision = service.controller.config.supervision

    def scenario() -> None:
        record = fault_during_motion(client, lambda: setattr(actuators[1].inject, "stall", True), duration_s=6.0)
        assert codes(record)[0] == ("following_error", 2), record["faults"]
        assert f"(limit {supervision.following_error_mm:g} mm): jammed" in record["faults"][0]["message"]
        assert_held(client)
        # Found from outside: the jammed leg was held at its set-point, its motor pushing
        # against the jam, as long as FAULT lasted. It is released (DISABLE: brake on); the
        # others hold.
        legs = wait_for(lambda: (legs := status(client)["legs"])[1]["state"] == "disabled" and legs,
                        "the jammed leg released")
        assert [leg["state"] for leg in legs] == ["enabled", "disabled"] + ["enabled"] * 4, legs
        assert status(client)["state"] == "fault"
        actuators[1].inject.stall = False
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, {("following_error", 2)},
                           lambda: clear_injections(service))


def _locked(client: HexactlClient, leg: int) -> None:
    """Enabled and at rest, with ``leg`` locked."""
    recover(client)
    if status(client)["locked_leg"] != leg:
        client.request("leg_unlock")
        client.call("leg_lock", leg=leg)
    wait_for(lambda: status(client)["legs"][leg - 1]["state"] == "locked", f"leg {leg} locked")


def test_a_locked_leg_that_slips_on_its_brake_is_a_fault(client, actuators, service) -> None:
    """Found from outside: a locked leg was not supervised at all. Its brake let it creep
    10 mm and nothing said so; moves went on planned as if it had kept its length; and
    unlocking asked the actuator, which follows from where it measures, for the whole
    10 mm in one step (SETPOINT_RANGE on the firmware)."""
    supervision = service.controller.config.supervision

    def scenario() -> None:
        _locked(client, 3)
        actuators[2].inject.brake_slip_um_s = -2000.0  # 2 mm/s
        record = wait_for(lambda: (record := status(client))["state"] == "fault" and record, "the fault to latch")
        assert codes(record)[0] == ("locked_leg_slipped", 3), record["faults"]
        message = record["faults"][0]["message"]
        assert message.startswith("leg 3 is -") and " mm from where it was locked for " in message, message
        assert f"(limit {supervision.locked_slip_mm:g} mm): its brake slips" in message, message
        assert_held(client)
        actuators[2].inject.brake_slip_um_s = 0.0
        back_in_service(client)  # the reset ended the lock
        assert status(client)["locked_leg"] is None

    tolerating_loop_stalls(scenario, lambda: service.controller, {("locked_leg_slipped", 3)},
                           lambda: clear_injections(service))


def test_a_locked_leg_that_crept_within_the_limit_unlocks_without_a_jump(client, actuators, service) -> None:
    """Within ``locked_slip_mm`` the creep is tolerated, and unlocking asks the actuator
    (which follows from where it measures) for no more than one step allows."""
    supervision = service.controller.config.supervision

    def scenario() -> None:
        _locked(client, 4)
        held = status(client)["leg_setpoints"][3]
        actuators[3].inject.brake_slip_um_s = 1000.0
        wait_for(lambda: status(client)["leg_feedback"][3] >= held + supervision.locked_slip_mm / 2, "the creep")
        actuators[3].inject.brake_slip_um_s = 0.0
        client.call("leg_unlock")
        client.call("move", pose=[0, 0, 20, 0, 0, 0], duration=0.5)
        wait_for(lambda: (record := status(client))["motion"] == "holding" and record["goal"] is None,
                 "the move after the unlock")
        record = status(client)
        assert record["state"] == "enabled" and record["faults"] == [], record["faults"]
        assert record["legs"][3]["state"] == "enabled"

    tolerating_loop_stalls(scenario, lambda: service.controller, (), lambda: clear_injections(service))


def test_a_short_burst_of_lost_or_corrupted_frames_is_ridden_through(client, actuators, service) -> None:
    """Two frames lost, then two corrupted: at most one missed cycle each, inside the
    actuator's watchdog; the corrupted ones are rejected and reported in its heartbeat."""
    link: CanActuatorLink = service.controller.hardware

    def scenario() -> None:
        recover(client)
        rejected = link.stats().rejected_frames[1]
        client.call("move", pose=[0, 0, -40, 0, 0, 0], duration=1.0)
        actuators[1].inject.drop_next = 2
        wait_for(lambda: actuators[1].inject.drop_next == 0, "the frames to be dropped")
        actuators[1].inject.corrupt_next = 2
        wait_for(lambda: link.stats().rejected_frames[1] >= rejected + 2, "the rejections in a heartbeat")
        wait_for(lambda: status(client)["motion"] == "holding", "the move to end")
        record = status(client)
        assert (record["state"], record["faults"]) == ("enabled", [])
        assert record["pose_command"] == pytest.approx([0, 0, -40, 0, 0, 0], abs=1e-6)

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: clear_injections(service))


@pytest.mark.parametrize("loss", ["drop_probability", "corrupt_probability"])
def test_lasting_frame_loss_trips_the_actuator_watchdog(client, actuators, service, loss) -> None:
    """Leg 2 receives nothing usable: its watchdog stops it with COMM_TIMEOUT, it says so
    (EMCY), and the loop latches FAULT."""

    def scenario() -> None:
        record = fault_during_motion(client, lambda: setattr(actuators[1].inject, loss, 1.0), z_mm=-60.0)
        assert codes(record)[0] == ("actuator_fault", 2)
        assert record["faults"][0]["message"].endswith("faults: comm_timeout (0x1)")
        assert_held(client)
        setattr(actuators[1].inject, loss, 0.0)
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, {("actuator_fault", 2)}, lambda: clear_injections(service))


class VanishingBus:
    """The link's bus behind a switch: while ``down``, every send and receive fails with
    ENETDOWN, as SocketCAN does for an interface that went down or was unplugged."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.down = False

    def _check(self) -> None:
        if self.down:
            raise can.CanOperationError("Failed to transmit: Network is down", error_code=errno.ENETDOWN)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check()
        self.bus.send(msg, timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        self._check()
        return self.bus.recv(timeout)

    def shutdown(self) -> None:
        self.bus.shutdown()


@pytest.fixture
def vanishing_bus(service: Service) -> Iterator[VanishingBus]:
    """The service's link on a :class:`VanishingBus` (the link has no seam for this: its
    private bus is swapped, and swapped back after the test)."""
    link = service.controller.hardware
    original = link._bus
    link._bus = switch = VanishingBus(original)
    yield switch
    switch.down = False
    link._bus = original


def test_the_bus_going_away(client, service, vanishing_bus) -> None:
    def scenario() -> None:
        record = fault_during_motion(client, lambda: setattr(vanishing_bus, "down", True))
        assert codes(record)[0] == ("link_failed", None)
        assert "bus down" in record["faults"][0]["message"] and "Network is down" in record["faults"][0]["message"]
        assert_held(client)
        vanishing_bus.down = False
        # Without set-points the actuators' watchdogs stopped them: COMM_TIMEOUT, holding on their brakes.
        wait_for(lambda: all(actuator.state is ActuatorState.FAULT and actuator.fault_bits & Fault.COMM_TIMEOUT
                             for actuator in service.controller.snapshot.feedback.actuators), "the actuators' report")
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: setattr(vanishing_bus, "down", False))


def test_reset_cannot_enable_while_the_bus_is_away(client, service, vanishing_bus) -> None:
    def scenario() -> None:
        fault_during_motion(client, lambda: setattr(vanishing_bus, "down", True))
        client.call("reset")
        wait_for(lambda: status(client)["state"] == "disabled", "the reset")
        with pytest.raises(CommandError) as refused:
            client.call("enable")
        assert refused.value.code in ("heartbeat_missing", "actuator_fault", "send_failed")
        vanishing_bus.down = False
        back_in_service(client)

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: setattr(vanishing_bus, "down", False))
