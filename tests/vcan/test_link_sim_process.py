"""The controller link on real SocketCAN (vcan0) against the simulator in a separate process
(``hexactl sim-actuators``), with a python-can capture decoded by the cantools CLI.

Collected only where vcan0 exists (tests/conftest.py); elsewhere tests/test_vcan_in_uml.py runs
them inside user-mode Linux, whose kernel ticks at 100 Hz: sleeps last up to 10 ms, so the loop
here declares 250 Hz with a 100-cycle watchdog (0.4 s, the protocol's longest) and asserts
nothing about timing. A guest that the host stops for longer than that (a busy host) stops
the actuators by their watchdog, as it should: each test then runs again from a new
simulator and link (:func:`attempts`), and fails on anything else.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import can
import pytest

from firmware_proto import DBC_PATH, codec
from firmware_proto.codec import Fault, LoopRate
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.can.transport import open_bus
from hexactl.control.hardware import ActuatorCommand, ActuatorState, FeedbackSnapshot
from tests.reliability.support import ATTEMPTS
from tests.vcan.test_service_over_vcan import SIMULATOR_TICK_MS

pytestmark = pytest.mark.vcan

SPEC = "socketcan:vcan0"
START_MM = (300.0, 310.0, 320.0, 330.0, 340.0, 350.0)
CONFIG = LinkConfig(loop_rate=LoopRate.HZ_250, watchdog_cycles=100)
PERIOD_S = 1 / CONFIG.loop_rate
WATCHDOG_S = (CONFIG.watchdog_cycles + 0.5) * PERIOD_S
DEADLINE_S = 10.0  # for anything to happen; generous for a slow guest
ANALYSER_BUFFER_BYTES = 64 << 20
"""The analyser's receive buffer (about 80 000 frames): its thread shares the GIL with the
loop here, and frames that find a full buffer are lost to the capture."""


class Simulator:
    """``hexactl sim-actuators`` in its own process."""

    def __init__(self) -> None:
        positions = ",".join(str(p) for p in START_MM)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hexactl.adapters.cli.main", "sim-actuators", "--can", SPEC,
             "--positions", positions, "--seed", "3", "--tick-ms", str(SIMULATOR_TICK_MS)],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        ready = json.loads(self.process.stdout.readline() or "{}")
        assert ready.get("ready"), self.process.stderr.read()

    def stop(self) -> dict:
        """SIGTERM; the simulator's final report."""
        self.process.send_signal(signal.SIGTERM)
        out, err = self.process.communicate(timeout=DEADLINE_S)
        assert self.process.returncode == 0, err
        return json.loads(out.strip().splitlines()[-1])


class Loop:
    """A paced control loop: one cycle of set-points, then the feedback, every period."""

    def __init__(self, link: CanActuatorLink) -> None:
        self.link = link
        self.counter = 0
        self.snapshot = link.read_feedback()
        self.expect_watchdog = False  # set by a scenario that stalls on purpose

    def run(self, cycles: int, setpoints: Callable[[int], Sequence[float]] | None = None) -> FeedbackSnapshot:
        for k in range(cycles):
            if setpoints is not None:
                self.link.send_setpoints(self.counter, setpoints(k))
                self.counter += 1
            time.sleep(PERIOD_S)
            self.snapshot = self.link.read_feedback()
        return self.snapshot

    def until(self, condition: Callable[[FeedbackSnapshot], bool], setpoints=None, what: str = "") -> FeedbackSnapshot:
        end = time.monotonic() + DEADLINE_S
        while not condition(self.run(1, setpoints)):
            assert time.monotonic() < end, f"timed out waiting for {what}: {self.snapshot}"
        return self.snapshot

    def hold(self, positions: Sequence[float]) -> Callable[[int], Sequence[float]]:
        return lambda k: positions

    def states(self) -> list[ActuatorState]:
        return [a.state for a in self.snapshot.actuators]

    def enable(self) -> tuple[float, ...]:
        """Wait for positions and heartbeats (ENABLE needs the protocol version), enable all
        six; returns the positions enabled at."""
        self.until(
            lambda s: all(a.position_mm == a.position_mm for a in s.actuators)
            and all(self.link.node_status(leg).protocol_version == codec.PROTOCOL_VERSION for leg in range(1, 7)),
            what="feedback and heartbeats",
        )
        positions = self.snapshot.positions_mm
        assert self.link.send_command(None, ActuatorCommand.ENABLE)
        self.until(lambda s: all(a.state is ActuatorState.ENABLED for a in s.actuators), self.hold(positions),
                   "ENABLED")  # fmt: skip
        return positions


class FeedbackWatch(can.Listener):
    """Sets ``reached`` once one actuator's feedback, as received on this listener's socket,
    reports at least ``at_least_um``."""

    def __init__(self, node: int, at_least_um: int) -> None:
        self.can_id = codec.NodeFrameBase.FEEDBACK + node
        self.target_um = at_least_um
        self.position_um: int | None = None
        self.reached = threading.Event()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == self.can_id:
            self.position_um = codec.decode_feedback(msg.arbitration_id, bytes(msg.data)).position_um
            if self.position_um >= self.target_um:
                self.reached.set()


def all_in(state: ActuatorState) -> Callable[[FeedbackSnapshot], bool]:
    return lambda s: all(a.state is state for a in s.actuators)


@contextmanager
def simulated_link() -> Iterator[tuple[Simulator, Loop]]:
    """A new simulator process and a link to it; the simulator killed on leaving unless it
    has ended (:meth:`Simulator.stop` ends it cleanly)."""
    simulator = Simulator()
    try:
        with CanActuatorLink.open(SPEC, CONFIG) as link:
            yield simulator, Loop(link)
    finally:
        if simulator.process.poll() is None:
            simulator.process.kill()
            simulator.process.wait()


def attempts(scenario: Callable[[Simulator, Loop], None]) -> None:
    """Run ``scenario`` with a new simulator and link; again, :data:`ATTEMPTS` in all, if it
    failed with an actuator stopped by its watchdog (COMM_TIMEOUT) where the scenario had not
    made one: the guest was held up past the watchdog. Each such attempt is printed."""
    for attempt in range(1, ATTEMPTS + 1):
        with simulated_link() as (simulator, loop):
            try:
                scenario(simulator, loop)
                return
            except AssertionError as error:
                if attempt == ATTEMPTS or loop.expect_watchdog or not any(
                        a.fault_bits & Fault.COMM_TIMEOUT for a in loop.snapshot.actuators):
                    raise
                print(f"attempt {attempt} stopped by the actuators' watchdog (a held-up guest): {error!r:.300}")


def test_enable_stream_follow_and_the_capture_decodes_with_the_dbc(tmp_path: Path):
    attempts(lambda simulator, loop: follow_and_decode(simulator, loop, tmp_path / "capture.log"))


def follow_and_decode(simulator: Simulator, loop: Loop, capture: Path) -> None:
    link = loop.link
    analyser = open_bus(SPEC, receive_buffer_bytes=ANALYSER_BUFFER_BYTES)  # its thread may lag a busy guest
    logger = can.Logger(str(capture))  # python-can's .log is candump -L format
    leg_3 = FeedbackWatch(node=3, at_least_um=329_999)
    notifier = can.Notifier(analyser, [logger, leg_3])
    try:
        start = loop.enable()
        assert start == START_MM
        ramp = lambda k: [p + 0.1 * min(k, 100) for p in start]  # noqa: E731  10 mm, ≤ 25 mm/s
        loop.run(100, ramp)
        loop.until(lambda s: all(abs(p - (q + 10.0)) <= 0.001 for p, q in zip(s.positions_mm, start)),
                   lambda k: ramp(100), "the ramp's end")  # fmt: skip
        assert all(a.setpoint_counter >= 100 for a in loop.snapshot.actuators)
        health = link.link_health()
        assert health.send_failures == 0 and link.stats().undecodable_frames == 0
        # The analyser reads its own socket on its own thread and may lag behind the loop: stopping
        # it now would drop the frames still queued in that socket, so wait until it has the last
        # feedback the loop saw.
        assert leg_3.reached.wait(DEADLINE_S), f"the capture's last leg-3 feedback: {leg_3.position_um} µm"
    finally:
        notifier.stop()
        logger.stop()
        analyser.shutdown()
    report = simulator.stop()
    assert report["states"] == ["ENABLED"] * 6 and report["rejected_frames"] == [0] * 6

    decoded = subprocess.run(
        [sys.executable, "-m", "cantools", "decode", "--single-line", str(DBC_PATH)],
        stdin=capture.open(), capture_output=True, text=True, timeout=120, check=True,
    ).stdout
    setpoints = [int(v) for v in re.findall(r"SETPOINT_12\(Setpoint1: (-?\d+) um", decoded)]
    syncs = re.findall(r"SYNC\(Counter: (\d+)", decoded)
    feedback = [int(v) for v in re.findall(r"FEEDBACK_3\(Position: (-?\d+) um", decoded)]
    assert setpoints and min(setpoints) == 300_000 and max(setpoints) == 310_000
    assert len(syncs) >= len(setpoints)  # bare SYNCs before the first set-points
    # Leg 3 went from 320 mm to 330 mm (its last reports within 1 µm, as the loop checked above).
    assert feedback and all(320_000 <= v <= 330_001 for v in feedback) and max(feedback) >= 329_999
    assert "HEARTBEAT_6(State: ENABLED" in decoded and "CMD_ACK_1(Command: ENABLE" in decoded


def test_watchdog_trips_latches_and_needs_clear_fault_then_enable():
    attempts(watchdog_trips)


def watchdog_trips(simulator: Simulator, loop: Loop) -> None:
    link = loop.link
    start = loop.enable()
    loop.run(20, loop.hold(start))
    loop.expect_watchdog = True
    time.sleep(WATCHDOG_S + 0.2)  # the loop stalls: nothing is sent
    loop.until(all_in(ActuatorState.FAULT), what="COMM_TIMEOUT")
    assert all(a.fault_bits == Fault.COMM_TIMEOUT for a in loop.snapshot.actuators)
    loop.run(50, loop.hold(start))  # set-points alone do not resume
    assert loop.states() == [ActuatorState.FAULT] * 6
    link.send_command(None, ActuatorCommand.CLEAR_FAULT)
    loop.until(all_in(ActuatorState.DISABLED), loop.hold(start), "DISABLED")
    link.send_command(None, ActuatorCommand.ENABLE)
    loop.until(all_in(ActuatorState.ENABLED), loop.hold(start), "ENABLED again")
    assert loop.snapshot.positions_mm == start


def test_emergency_stop_latches_and_wins():
    attempts(estop_latches)


def estop_latches(simulator: Simulator, loop: Loop) -> None:
    link = loop.link
    start = loop.enable()
    assert link.send_estop()
    loop.until(all_in(ActuatorState.ESTOP), loop.hold(start), "ESTOP")
    link.send_command(None, ActuatorCommand.ENABLE)  # refused: ESTOP wins
    loop.run(30, lambda k: [p + 0.1 * k for p in start])
    assert loop.states() == [ActuatorState.ESTOP] * 6 and loop.snapshot.positions_mm == start
    time.sleep(0.3)  # the actuators clear ESTOP only 250 ms after the last ESTOP frame
    link.send_command(None, ActuatorCommand.CLEAR_FAULT)
    loop.until(all_in(ActuatorState.DISABLED), loop.hold(start), "DISABLED")
    assert all(a.fault_bits == 0 for a in loop.snapshot.actuators)


def test_corrupted_crc_and_replayed_counter_are_ignored_and_counted():
    attempts(rejections_counted)


def rejections_counted(simulator: Simulator, loop: Loop) -> None:
    link = loop.link
    start = loop.enable()
    injector = open_bus(SPEC)  # a second node on the bus: it hears the link's frames and sends its own
    try:
        loop.run(10, loop.hold(start))
        heard = []
        while (message := injector.recv(0.0)) is not None:
            heard.append((message.arbitration_id, bytes(message.data)))
        setpoint_12 = [frame for frame in heard if frame[0] == codec.FrameId.SETPOINT_12][-1]
        sync = [frame for frame in heard if frame[0] == codec.FrameId.SYNC][-1]
        far = codec.encode_setpoints(loop.counter & 0xFF, [round(p * 1000) + 700 for p in start])
        corrupted = [(can_id, payload[:-1] + bytes((payload[-1] ^ 0x5A,))) for can_id, payload in far]
        for can_id, payload in [*corrupted, setpoint_12, sync]:
            injector.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
        time.sleep(0.25)  # past the next heartbeat, which reports the rejections
        loop.run(30, loop.hold(start))
    finally:
        injector.shutdown()
    assert loop.snapshot.positions_mm == start and loop.states() == [ActuatorState.ENABLED] * 6
    assert link.stats().rejected_frames == (4, 4, 3, 3, 3, 3)
    assert simulator.stop()["rejected_frames"] == [4, 4, 3, 3, 3, 3]
