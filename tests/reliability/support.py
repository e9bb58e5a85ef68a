"""Helpers of the reliability suite."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager

import pytest

from firmware_proto.codec import Fault
from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.application.service import Service
from hexactl.control.local_controller import LocalController
from hexactl.sim.actuator_firmware import ActuatorFirmware
from tests.api.test_service import status, wait_for
from tools.serving import HANG_S, Served, spawned_children, wait_until

LOCAL = "tcp://127.0.0.1:*"
RATE_HZ = 500
RESET_RETRY_S = 0.1  # a reset's CLEAR_FAULT may wait up to the E-stop hold-off (0.3 s)
ATTEMPTS = 3
BOOTING = ("heartbeat_missing", "outside_stroke", "pose_unknown")
"""Refusals of enable while the actuators boot: heard, but no FEEDBACK yet (position NaN)."""
NOT_YET = (*BOOTING, "loop_timeout")
"""Answers to enable that call for asking again: booting, or no verdict in time from a loop
held up on a busy host (it may still enable: asked again, it answers that it already is)."""


def firmwares(service: Service) -> tuple[ActuatorFirmware, ...]:
    """The service's six simulated actuator firmwares, for their ``inject``
    (:class:`~hexactl.sim.actuator_firmware.FaultInjection`)."""
    return service.simulator.runner.firmwares


def clear_injections(service: Service) -> None:
    """Switch every injected fault of the service's actuators off."""
    for firmware in firmwares(service):
        injection = firmware.inject
        injection.silent = injection.stall = injection.sensor_fault = False
        injection.brake_slip_um_s = 0.0
        injection.drop_probability = injection.corrupt_probability = 0.0
        injection.drop_next = injection.corrupt_next = 0


def enable(client: HexactlClient) -> None:
    """Enable, waiting while the actuators boot and report their positions; an actuator
    still in FAULT (its CLEAR_FAULT was refused while the cause lasted) gets another
    ``reset``, as an operator would give it."""

    def attempt() -> bool:
        try:
            client.call("enable")
        except CommandError as error:
            if error.code == "actuator_fault":
                client.call("reset")
                time.sleep(RESET_RETRY_S)
                return False
            assert error.code in NOT_YET, error
            return False
        return True

    wait_for(attempt, "the actuators to enable")


def recover(client: HexactlClient) -> None:
    """From any state to enabled and at rest: reset whatever is latched, enable."""
    if status(client)["state"] in ("fault", "estop"):
        reply = client.request("reset")
        assert reply["ok"] or reply["error"]["code"] == "loop_timeout", reply  # then carried out a moment later
        wait_for(lambda: status(client)["state"] == "disabled", "the reset")
    enable(client)
    wait_for(lambda: status(client)["motion"] == "holding", "the platform at rest")


@contextmanager
def recovered_client(api: str, timeout_s: float) -> Iterator[HexactlClient]:
    """A client of the service at ``api`` that finds the platform enabled and at rest,
    whatever was latched before (:func:`recover`)."""
    with HexactlClient(api, timeout_s=timeout_s) as client:
        recover(client)
        yield client


def recovered_client_fixture(timeout_s: float):  # -> a pytest fixture
    """A ``client`` fixture (:func:`recovered_client`) for a module whose ``served``
    fixture shares one ``hexactl serve`` between its tests."""

    @pytest.fixture
    def client(served: Served) -> Iterator[HexactlClient]:
        with recovered_client(served.api, timeout_s) as connected:
            yield connected

    return client


STALL_FAULTS = ("heartbeat_lost", "setpoints_not_applied")
"""Faults the loop latches when it was held up itself (besides the actuators' watchdog)."""


def stall_fault(controller: LocalController, expected: Collection[tuple[str, int]] = ()) -> bool:
    """Whether ``controller`` shows what a held-up loop causes, other than the faults
    ``expected`` by the scenario ((code, leg) pairs; an actuator's COMM_TIMEOUT counts as
    ``actuator_fault``): an actuator stopped by its watchdog (COMM_TIMEOUT: a stall stops
    them all), or, as the first latched fault, a heartbeat the loop did not read in time
    or set-points it did not send in time."""
    snapshot = controller.snapshot
    if snapshot.feedback is None:
        return False
    if any(actuator.fault_bits & Fault.COMM_TIMEOUT and ("actuator_fault", leg) not in expected
           for leg, actuator in enumerate(snapshot.feedback.actuators, start=1)):
        return True
    first = snapshot.faults[0] if snapshot.faults else None
    return first is not None and first.code in STALL_FAULTS and (first.code, first.leg) not in expected


def tolerating_loop_stalls(scenario: Callable[[], None], controller: Callable[[], LocalController | None],
                           expected: Collection[tuple[str, int]] = (), cleanup: Callable[[], None] = lambda: None) -> None:
    """Run ``scenario``; if it fails while the controller it drives (``controller()``)
    shows a stall's faults other than those ``expected`` (:func:`stall_fault`), ``cleanup()``
    and run it again (:data:`ATTEMPTS` in all). Each failed attempt prints the latched faults.

    The loop, the simulated actuators and the API share one process and the host's cores:
    on a loaded machine the loop can be held up longer than the actuators' watchdog or
    the heartbeat supervision, which then do their job. That is not what these scenarios
    test; a fault of their own fails every attempt (and the bus monitor checks them all).
    """
    for attempt in range(1, ATTEMPTS + 1):
        try:
            scenario()
            return
        except (AssertionError, CommandError) as error:  # a refusal of ``client.call`` fails a scenario too
            driven = controller()
            print(f"attempt {attempt} failed: {error!r:.300}; latched: {driven.snapshot.faults if driven else None}")
            if attempt == ATTEMPTS or driven is None or not stall_fault(driven, expected):
                raise
            cleanup()


def is_stall(fault: dict) -> bool:
    """Whether a latched fault (as in a status record) is one a held-up loop causes on a
    loaded host: the actuators' watchdog (COMM_TIMEOUT), the loop's heartbeat or set-point
    supervision."""
    return fault["code"] in STALL_FAULTS or (fault["code"] == "actuator_fault"
                                             and fault["message"].endswith("faults: comm_timeout (0x1)"))


def stalled(client: HexactlClient) -> bool:
    """Whether every fault latched is a stall's (:func:`is_stall`): the service did its
    job, but not what these tests are about."""
    faults = status(client)["faults"]
    return bool(faults) and all(map(is_stall, faults))


SILENCE_BRAKE = "command_link_silent"
"""The event of the service's own brake when its API process fell silent (starved of CPU on
a loaded host): the motion under way stops short of its goal and the platform holds,
enabled, with no fault latched."""


def last_event(record: dict) -> int:
    """The number of the latest of the loop's events in a status record (0 before any)."""
    return record["events"][-1]["seq"] if record["events"] else 0


def silence_braked(record: dict, after: int) -> bool:
    """Whether a status record's events say the service braked on its API's silence after
    event number ``after`` (a record carries the latest few: enough between two polls)."""
    return any(event["code"] == SILENCE_BRAKE and event["seq"] > after for event in record["events"])


def braked_since(client: HexactlClient, after: int) -> bool:
    """Whether the service braked on its API's silence after event number ``after``,
    from all the events it keeps."""
    return any(event["code"] == SILENCE_BRAKE for event in client.call("events", after=after)["events"])


STALL_REPLIES = ("loop_timeout",)
"""Replies that say the host held the loop up, not that the command was wrong: the loop gave
no verdict within the API's time limit (the command may still have been carried out)."""


def tolerating_stalls(client: HexactlClient, scenario: Callable[[], None], cleanup: Callable[[], None] = lambda: None) -> None:
    """Run ``scenario``; again from enabled and at rest (``cleanup()`` first) if it failed
    with only a stall's faults latched, after the service braked on its API's silence
    (:data:`SILENCE_BRAKE`), or on a reply of :data:`STALL_REPLIES`, :data:`ATTEMPTS` in all."""
    for attempt in range(1, ATTEMPTS + 1):
        since = last_event(status(client))
        try:
            scenario()
            return
        except (AssertionError, CommandError) as error:  # a stall latched between two steps refuses the next one
            braked = braked_since(client, since)
            held_up = isinstance(error, CommandError) and error.code in STALL_REPLIES
            print(f"attempt {attempt} failed: {error!r:.300}; latched: {status(client)['faults']}"
                  + ("; the service braked when its API fell silent" if braked else ""))
            if attempt == ATTEMPTS or not (stalled(client) or braked or held_up):
                raise
            cleanup()
            recover(client)


def hold_up_api(served: Served) -> None:
    """Hold the API process of ``served`` (a ``hexactl serve``) up, as a starved host
    does, here by SIGSTOP, until the service's log says it has noticed the silence."""
    [api_process] = spawned_children(served.process.pid)
    os.kill(api_process, signal.SIGSTOP)
    try:
        wait_until(lambda: "nothing from the API process for" in served.log, "the service to see the silence",
                   HANG_S, seen=lambda: served.log)
    finally:
        os.kill(api_process, signal.SIGCONT)
