"""The service is killed mid-motion and a new one takes over the same actuators, over real
SocketCAN with the simulated actuators in another process: the two-process version of
tests/reliability/test_controller_restart.py.

``kill -9`` of the service (what tests/vcan/test_service_over_vcan.py runs as
:data:`~tests.vcan.test_service_over_vcan.SERVE`, with the guest's 250 Hz and 0.4 s
watchdog) while the platform moves: its API process must end too (it would otherwise hold
the old endpoints, serving nothing); every actuator stops on its own watchdog (EMCY
COMM_TIMEOUT), latches FAULT and holds where it stopped; a new service starts disabled,
finds them latched (``enable`` refused, ``actuator_fault``), and after ``reset`` enables
from where they stand: the bus monitor sees each leg's first set-point equal to the
position it reported, and no violation from before the first enable to the end.

Collected only where vcan0 exists; elsewhere tests/test_vcan_in_uml.py runs it inside
user-mode Linux (the guest's timing: test_service_over_vcan.py's docstring). There the
simulator and the service, under SCHED_FIFO, leave this process a sliver of the one CPU,
far too little to read the bus as fast as a service fills it (about 1750 frames/s), and
whatever it spends reading it would not spend seeing the move under way and killing the
service before the move ends. So the bus is *captured*: the test's socket, opened before
anything else starts, gets a receive buffer for the whole test's traffic
(:data:`CAPTURE_BYTES`), and the monitor and :class:`FrameWatch` read it once everything
has stopped, with the frames' kernel timestamps. What needs seeing during the test, the
service's status says. A starved guest can also hold the service's loop past the
actuators' watchdog before the kill or on the way home, or hold up its API process until
the service brakes the move on its silence: such a move is tried again
(:func:`move_through_stalls`), and a kill that came after a stall had stopped the move is
done again (:func:`kill_mid_motion`). Nothing here asserts timing: the waits are generous bounds
that turn a hang into a failure.
"""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can
import pytest

from firmware_proto import codec
from firmware_proto.codec import ActuatorState, Fault, FaultCode
from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.can.bus_monitor import BusMonitor
from hexactl.adapters.can.transport import open_bus
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import default_config_path
from tests.reliability.support import ATTEMPTS, STALL_FAULTS, braked_since, enable, last_event, silence_braked
from tests.vcan.test_service_over_vcan import (
    POSE_ABS,
    RATE_HZ,
    SPEC,
    WAIT_S,
    Served,
    arrived,
    enabled_at_rest,
    running_service,
    simulated_actuators,
    status,
    terminate_service,
    terminate_simulator,
    wait_for,
    wait_status,
)

pytestmark = pytest.mark.vcan

LEGS = (1, 2, 3, 4, 5, 6)
UNDER_WAY = [0.0, 0.0, 150.0, 0.0, 0.0, 0.0]
"""The interrupted move's goal, mm and deg relative to the zero posture."""
HOME = [0.0] * 6
MOVE_S = 6.0
"""Duration of either move, s: time to spare for the starved test process to see the
first one under way and kill the service before it ends."""
UNDER_WAY_Z_MM = 30.0
"""The kill comes once the commanded z has passed this (a fifth of the way)."""
MOVING_S = 0.5
"""The set-points must have changed in this long before the kill, s: it came mid-motion."""
HOLD_S = 0.2
"""How long the stopped actuators must report the same position, s."""
COAST_MM = 5.0
"""How far an actuator may stop from where it last reported following: it goes on to its
last target (drive lag 5 ms) until its watchdog stops it, then brakes."""
TAKEOVER_ABS = 0.001
"""Commanded against measured pose at the takeover, mm and deg (as the in-process test)."""
SAME_MM = 1e-6
"""Set-points and positions that are the same µm on the wire, compared as floats, mm."""
JUMP_MM = 0.001
"""Largest first set-point step from the reported position: one µm of wire rounding."""
CAPTURE_BYTES = 256 << 20
"""The capture's receive buffer: the kernel doubles it and charges 768 bytes per queued
classic frame (measured in the guest), so it holds about 700 000 frames, over six minutes
of a service at 250 Hz (about 1750 frames/s: four set-point frames and six FEEDBACK a
cycle); only what is queued takes memory."""
_COMM_TIMEOUT_ONLY = re.compile(r"faults: comm_timeout \(0x1\)")


@dataclass(frozen=True, slots=True)
class Heard:
    """A decoded frame and its receive time (the kernel's, wall clock, s)."""

    when: float
    message: codec.Feedback | codec.Emergency | codec.SetpointFrame


class FrameWatch(can.Listener):
    """The FEEDBACK, EMCY and set-point frames (classic profile), decoded with
    :mod:`firmware_proto.codec`, in order: what the actuators say about themselves (state,
    fault bits, velocity, position), which the service's status does not show, and what a
    controller last told them."""

    KINDS = (codec.Feedback, codec.Emergency, codec.SetpointFrame)

    def __init__(self) -> None:
        self.heard: list[Heard] = []

    def on_message_received(self, msg: can.Message) -> None:
        try:
            message = codec.decode(msg.arbitration_id, bytes(msg.data))
        except codec.FrameError:
            return  # not a frame of the protocol: the monitor judges the controller's frames
        if isinstance(message, self.KINDS):
            self.heard.append(Heard(msg.timestamp, message))

    def between(self, kind: type, from_s: float, to_s: float) -> list[Heard]:
        """The frames of ``kind`` received from ``from_s`` up to ``to_s`` (wall clock, s)."""
        return [heard for heard in self.heard if isinstance(heard.message, kind) and from_s <= heard.when < to_s]

    def last_setpoints_mm(self, before_s: float) -> dict[int, float]:
        """Each leg's last set-point sent before ``before_s``, mm."""
        return {heard.message.first_node + i: value_um / 1000.0
                for heard in self.between(codec.SetpointFrame, 0.0, before_s)
                for i, value_um in enumerate(heard.message.positions_um)}  # fmt: skip


def open_capture() -> can.BusABC:
    """The test's socket on :data:`SPEC`, with a receive buffer of :data:`CAPTURE_BYTES`.

    :raises AssertionError: without the privilege for it (root): a smaller buffer would
        drop frames unnoticed while nobody reads
    """
    bus = open_bus(SPEC, receive_buffer_bytes=CAPTURE_BYTES)
    if bus.receive_buffer_bytes < CAPTURE_BYTES:
        bus.shutdown()
        raise AssertionError("capturing the bus for the whole test needs SO_RCVBUFFORCE: run it as root "
                             "(tools/uml_vcan.py's guest does)")
    return bus


def replay(bus: can.BusABC, listeners: list[can.Listener]) -> None:
    """Every frame captured on ``bus`` to each of ``listeners``, in order (nothing sends
    any more: the queue only empties)."""
    while (message := bus.recv(0.0)) is not None:
        for listener in listeners:
            listener.on_message_received(message)


@dataclass(frozen=True, slots=True)
class ProcessId:
    """A process by pid and start time (clock ticks since boot), so that a reused pid is
    not mistaken for it."""

    pid: int
    start_ticks: int
    cmdline: str

    def ended(self) -> bool:
        """Gone, a zombie (exited, not yet reaped: an orphan waits for init), or its pid reused."""
        fields = _stat(self.pid)
        return fields is None or fields[0] in "ZXx" or int(fields[19]) != self.start_ticks

    def describe(self) -> str:
        fields = _stat(self.pid)
        return f"pid {self.pid} ({self.cmdline}): " + ("gone" if fields is None else f"state {fields[0]}, ppid {fields[1]}")


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat's fields from the state on (proc(5)'s field 3 first); None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return text[text.rindex(")") + 2 :].split()  # the name in parentheses may hold spaces


def children(parent: int) -> list[ProcessId]:
    """The live child processes of ``parent``, found by their parent pid (which needs no
    CONFIG_PROC_CHILDREN)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or (fields := _stat(int(entry.name))) is None or int(fields[1]) != parent:
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except (FileNotFoundError, ProcessLookupError):
            continue
        found.append(ProcessId(int(entry.name), int(fields[19]), cmdline))
    return found


def stalled(faults: list[dict]) -> bool:
    """Whether latched ``faults`` are what a held-up loop causes: actuators stopped by
    their watchdogs alone (fault bits COMM_TIMEOUT), or first a heartbeat the loop did not
    read in time or set-points it did not send in time."""
    return bool(faults) and (faults[0]["code"] in STALL_FAULTS or all(
        fault["code"] == "actuator_fault" and _COMM_TIMEOUT_ONLY.search(fault["message"]) for fault in faults))  # fmt: skip


def move_through_stalls(client: HexactlClient, goal: list[float], reached: Callable[[dict], bool], what: str) -> dict:
    """Enable (unless enabled), move to ``goal`` over :data:`MOVE_S`, wait until
    ``reached`` takes a status record; that record. A move a stall of the starved guest
    stopped (:func:`stalled`), or that the service braked when the starved guest held up
    its API process (:func:`~tests.reliability.support.silence_braked`), is tried again,
    :data:`ATTEMPTS` in all; any other fault fails."""
    attempt = 1
    while True:
        since = last_event(enabled_at_rest(client))  # after a stall, it resets the fault
        try:
            client.call("move", pose=goal, duration=MOVE_S)
        except CommandError as error:  # a stall latched between the two: the move is refused
            if error.code != "latched":
                raise
        record = wait_status(client, lambda r: reached(r) or r["state"] != "enabled" or silence_braked(r, since), what)
        # A move braked on the API's silence ends at rest too, short of its goal: not reached.
        braked = braked_since(client, since)
        if record["state"] == "enabled" and reached(record) and not braked:
            return record
        by_stall = stalled(record["faults"]) if record["faults"] else braked
        assert attempt < ATTEMPTS and by_stall, (record["state"], record["faults"], record["events"])
        print(f"{what}: attempt {attempt} stopped by a stall of the guest: {record['faults'] or [e['code'] for e in record['events'] if e['seq'] > since]}")
        attempt += 1


@dataclass(frozen=True, slots=True)
class Takeover:
    """What the test saw live, for judging the capture: wall-clock times (s) just before
    the kill, just before the new service was started (the actuators answer the killed
    one's last SYNCs a moment after it is gone) and just before its ``reset``, and the
    positions the actuators held meanwhile by its status, mm."""

    killed_s: float
    restarted_s: float
    reset_s: float
    held_mm: list[float]


def test_killed_mid_motion_then_a_new_service_takes_over(tmp_path: Path) -> None:
    nominal = load_geometry(default_config_path())
    bus = open_capture()  # before anything starts: the monitor sees everything
    monitor, watch = BusMonitor(bus, nominal, RATE_HZ), FrameWatch()
    try:
        with simulated_actuators() as simulator:
            killed_s = kill_mid_motion(tmp_path, bus, [monitor, watch])
            restarted_s = time.time()
            with running_service(tmp_path) as second, HexactlClient(second.api, timeout_s=WAIT_S) as client:
                takeover = take_over(client, killed_s, restarted_s)
                terminate_service(second)
            terminate_simulator(simulator, tolerate_watchdog=True)  # a second take-over on a starved guest: seen 3 in 20
        replay(bus, [monitor, watch])
    finally:
        bus.shutdown()
    judge(watch, takeover, max(start.when for start in monitor.starts if start.when < takeover.restarted_s))
    starts = [start for start in monitor.starts if start.when > takeover.restarted_s]
    assert sorted({start.leg for start in starts}) == list(LEGS), starts
    assert all(start.jump_mm is not None and start.jump_mm <= JUMP_MM for start in starts), starts
    assert monitor.counts.get("unreferenced_starts", 0) == 0 and monitor.violations == [], monitor.violations


def kill_mid_motion(tmp_path: Path, bus: can.BusABC, listeners: list[can.Listener]) -> float:
    """Start a service, enable, start the long move, SIGKILL the service once under way
    (:func:`kill_under_way`); then check from the capture (read into ``listeners``, the
    last a :class:`FrameWatch`) that the set-points were still changing up to the kill. A
    stall of the starved guest can end the move before the kill (:func:`stall_before`);
    then it all happens again, the new service resetting what the killed one left latched,
    :data:`ATTEMPTS` in all. Returns the wall-clock time just before the kill that came
    mid-motion, s."""
    watch = listeners[-1]
    assert isinstance(watch, FrameWatch)
    attempt = 1
    while True:
        started_s = time.time()
        with running_service(tmp_path) as first:
            killed_s = kill_under_way(first, reset_first=attempt > 1)
        replay(bus, listeners)  # what the capture holds so far: only the simulator sends now
        if watch.last_setpoints_mm(time.time()) != watch.last_setpoints_mm(killed_s - MOVING_S):
            return killed_s
        stall = stall_before(watch, started_s, killed_s)
        assert attempt < ATTEMPTS and stall, f"the set-points stood still for {MOVING_S} s before the kill: {stall}"
        print(f"attempt {attempt}: the move was stopped before the kill by a stall of the guest, {stall}")
        attempt += 1


def stall_before(watch: FrameWatch, from_s: float, to_s: float) -> list[Heard]:
    """The actuators' EMCY COMM_TIMEOUT frames received from ``from_s`` up to ``to_s``
    (wall clock, s): their watchdogs stopped them, the loop having been held up."""
    return [heard for heard in watch.between(codec.Emergency, from_s, to_s)
            if heard.message.fault_code is FaultCode.COMM_TIMEOUT]  # fmt: skip


def kill_under_way(first: Served, reset_first: bool) -> float:
    """Enable (resetting first what a killed service left latched, if ``reset_first``), start the long move, SIGKILL the service once under way; check that
    its API process ends too. Returns the wall-clock time just before the kill, s."""
    spawned = children(first.process.pid)  # the API process and multiprocessing's resource tracker
    api = [child for child in spawned if "spawn_main" in child.cmdline]
    assert len(api) == 1, spawned
    with HexactlClient(first.api, timeout_s=WAIT_S) as client:
        if reset_first:
            enable(client)  # resets what is latched
        record = move_through_stalls(client, UNDER_WAY, lambda r: r["pose_command"][2] > UNDER_WAY_Z_MM,
                                     "the platform under way")  # fmt: skip
        assert record["motion"] == "moving", record

    # The crash: no stop, no DISABLE, no E-stop; the stream of set-points just ends.
    killed_s = time.time()
    first.process.kill()
    assert first.process.wait(WAIT_S) == -signal.SIGKILL

    wait_for(lambda: all(child.ended() for child in spawned),
             f"the killed service's processes to end: {[child.describe() for child in spawned]}")  # fmt: skip
    assert api[0].ended()
    return killed_s


def refused_as_latched(client: HexactlClient) -> bool:
    """Whether ``enable`` is refused because the actuators are latched in FAULT by their
    watchdogs (False while not every actuator has been heard).

    :raises AssertionError: if it is accepted or refused for another reason"""
    try:
        client.call("enable")
    except CommandError as error:
        if error.code == "heartbeat_missing":
            return False
        assert error.code == "actuator_fault" and _COMM_TIMEOUT_ONLY.search(error.message), error
        return True
    raise AssertionError("enable accepted actuators latched in FAULT")


def take_over(client: HexactlClient, killed_s: float, restarted_s: float) -> Takeover:
    """The new service (``client``'s) starts disabled, finds the actuators latched and
    holding, resets them and enables from where they stand, then moves home."""
    record = status(client)
    assert (record["state"], record["faults"]) == ("disabled", []), record
    wait_for(lambda: refused_as_latched(client), "enable refused with actuator_fault")
    before = status(client)
    # Twice the hold, by the service's clock: the capture then holds FEEDBACK over HOLD_S.
    after = wait_status(client, lambda r: r["t"] >= before["t"] + 2 * HOLD_S, "the actuators held")
    assert after["leg_feedback"] == before["leg_feedback"]  # on their brakes
    reset_s = time.time()

    client.call("reset")
    record = enabled_at_rest(client)
    assert record["pose_command"] == pytest.approx(record["pose_measured"], abs=TAKEOVER_ABS)
    assert record["leg_setpoints"] == pytest.approx(before["leg_feedback"], abs=SAME_MM)

    record = move_through_stalls(client, HOME, arrived, "the move home")
    assert record["pose_command"] == pytest.approx(HOME, abs=1e-6)
    assert record["pose_measured"] == pytest.approx(HOME, abs=POSE_ABS)
    return Takeover(killed_s, restarted_s, reset_s, before["leg_feedback"])


def judge(watch: FrameWatch, takeover: Takeover, session_s: float) -> None:
    """From the capture, ``session_s`` being when the killed service's last session began
    (its last ENABLE's first set-point, wall clock, s): the kill came mid-motion; every
    actuator stopped on its watchdog in that session (EMCY COMM_TIMEOUT; a stall of the
    starved guest just before the kill may have stopped it a moment earlier, the same way),
    no farther than :data:`COAST_MM` from where it last reported following, and reported
    FAULT, COMM_TIMEOUT, no velocity and the same position until the reset, over at least
    :data:`HOLD_S`."""
    assert sorted(watch.last_setpoints_mm(takeover.restarted_s)) == list(LEGS)
    emergencies = watch.between(codec.Emergency, session_s, takeover.reset_s)
    stopped = {heard.message.node for heard in emergencies if heard.message.fault_code is FaultCode.COMM_TIMEOUT}
    assert sorted(stopped) == list(LEGS), (takeover, emergencies)

    held_mm = dict(zip(LEGS, takeover.held_mm))
    following_mm = {heard.message.node: heard.message.position_um / 1000.0
                    for heard in watch.between(codec.Feedback, session_s, takeover.restarted_s)
                    if heard.message.state is ActuatorState.ENABLED}  # fmt: skip
    assert sorted(following_mm) == list(LEGS)
    assert all(abs(held_mm[leg] - following_mm[leg]) <= COAST_MM for leg in LEGS), (held_mm, following_mm)
    reports = watch.between(codec.Feedback, takeover.restarted_s, takeover.reset_s)
    for leg in LEGS:
        mine = [heard for heard in reports if heard.message.node == leg]
        assert mine and mine[-1].when - mine[0].when >= HOLD_S, f"leg {leg}: {mine}"
        assert all(heard.message.state is ActuatorState.FAULT and heard.message.faults & Fault.COMM_TIMEOUT
                   and heard.message.velocity_um_s == 0
                   and abs(heard.message.position_um / 1000.0 - held_mm[leg]) <= SAME_MM for heard in mine), mine  # fmt: skip
