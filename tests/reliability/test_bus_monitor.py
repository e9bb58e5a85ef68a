"""The bus monitor itself: it flags what it must, passes what it may, and agrees with the
codec on valid frames (while decoding with cantools, independently of it)."""

from __future__ import annotations

import itertools

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_proto import codec
from firmware_proto.codec import ActuatorState, CommandCode, Fault, LoopRate
from hexactl.adapters.can.bus_monitor import BusMonitor, crc8_sae_j1850, frame_crc
from hexactl.adapters.can.transport import IN_PROCESS_INTERFACES, IN_PROCESS_RX_QUEUE_SIZE, open_bus
from hexactl.kinematics.geometry import Geometry

RATE_HZ = 500
START_UM = (300_000, 310_000, 320_000, 330_000, 340_000, 350_000)
_channels = itertools.count()


class Feed:
    """Frames fed straight to a monitor with explicit timestamps, one loop period apart."""

    def __init__(self, geometry: Geometry) -> None:
        self.monitor = BusMonitor(f"virtual:monitor-unit-{next(_channels)}", geometry, RATE_HZ)  # not started: fed
        self.step_um = geometry.limits.leg_velocity_mm_s * 1000 / RATE_HZ  # 800 µm at 400 mm/s
        self.t_s = 0.0

    def frame(self, can_id: int, payload: bytes) -> None:
        self.monitor.on_message_received(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False,
                                                     timestamp=self.t_s))

    def cycle(self, counter: int, positions_um, periods: int = 1) -> None:
        """One whole cycle as the link sends it: SETPOINT_12, _34, _56 and SYNC."""
        self.t_s += periods / RATE_HZ
        for can_id, payload in codec.encode_setpoints(counter & 0xFF, [round(p) for p in positions_um]):
            self.frame(can_id, payload)

    def feedback(self, positions_um) -> None:
        for node, position in enumerate(positions_um, start=1):
            self.frame(*codec.encode_feedback(node, position, 0, ActuatorState.DISABLED, Fault(0), 0))

    def enable(self, sequence: int = 7, watchdog_cycles: int = 5) -> None:
        for node in range(1, 7):
            self.frame(*codec.encode_command(node, CommandCode.ENABLE, sequence, LoopRate.HZ_500, watchdog_cycles))

    def kinds(self) -> list[str]:
        return [violation.what for violation in self.monitor.violations]


@pytest.fixture
def feed(nominal) -> Feed:
    feed = Feed(nominal)
    yield feed
    feed.monitor.stop()


def test_crc_check_value_of_the_protocol() -> None:
    assert crc8_sae_j1850(b"123456789") == 0x4B


@given(counter=st.integers(0, 255), positions=st.lists(st.integers(-8_388_608, 8_388_607), min_size=6, max_size=6))
def test_crc_agrees_with_the_codec_on_every_setpoint_cycle(counter, positions) -> None:
    for can_id, payload in codec.encode_setpoints(counter, positions):
        assert frame_crc(can_id, payload) == payload[-1]


def test_a_ramp_at_the_limit_across_the_counter_wrap_passes(feed) -> None:
    feed.feedback(START_UM)
    feed.enable()
    for k in range(300):
        feed.cycle(k, [p + k * feed.step_um for p in START_UM])
    report = feed.monitor.report()
    assert feed.kinds() == []
    assert report.counts["cycles"] == 300 and report.counts["setpoints"] == 1800
    assert report.max_step_fraction == pytest.approx(1.0)
    assert [start.jump_mm for start in feed.monitor.starts] == [0.0] * 6


@pytest.mark.parametrize(("step_um", "flagged"), [(801, False), (802, True), (-802, True)])
def test_a_step_beyond_the_limit_and_rounding_is_flagged(feed, step_um, flagged) -> None:
    feed.feedback(START_UM)
    feed.enable()
    feed.cycle(0, START_UM)
    feed.cycle(1, [START_UM[0] + step_um, *START_UM[1:]])
    assert feed.kinds() == (["velocity"] if flagged else [])
    if flagged:
        assert "leg 1" in feed.monitor.violations[0].message


def test_set_points_outside_the_stroke_are_flagged(feed, nominal) -> None:
    low, high = (round(limit * 1000) for limit in nominal.limits.stroke)
    feed.cycle(0, [high - 500, low + 500, *START_UM[2:]])
    feed.cycle(1, [high + 1, low - 1, *START_UM[2:]])
    assert feed.kinds() == ["outside_stroke", "outside_stroke"]


def test_counter_gaps_allow_one_step_per_counter(feed) -> None:
    """Cycles that never reached the bus (a failed send) each allow a step; a counter
    beyond the watchdog window, or repeated, is one the actuator refuses: not checked."""
    feed.feedback(START_UM)
    feed.enable(watchdog_cycles=5)
    feed.cycle(0, START_UM)
    feed.cycle(3, [p + 3 * feed.step_um for p in START_UM], periods=3)  # 2.4 mm over 3 counters: fine
    assert feed.kinds() == []
    feed.cycle(4, [p + 5 * feed.step_um for p in START_UM])  # 1.6 mm in one counter
    assert feed.kinds() == ["velocity"] * 6
    feed.cycle(4, START_UM)  # repeated counter: stale
    feed.cycle(20, START_UM, periods=16)  # beyond the window of 5: refused by the actuator
    assert feed.monitor.counts["stale_setpoints"] == 12
    assert len(feed.monitor.violations) == 6


def test_enable_makes_the_measured_position_the_reference(feed) -> None:
    feed.feedback(START_UM)
    feed.enable(sequence=1)
    feed.cycle(0, START_UM)
    moved = [p + 50_000 for p in START_UM]  # the platform was moved while disabled
    feed.feedback(moved)
    feed.enable(sequence=2)
    feed.cycle(1, moved)
    assert feed.kinds() == []
    feed.enable(sequence=2)  # a retry of that ENABLE: not a new session
    feed.cycle(2, START_UM)
    assert feed.kinds() == ["velocity"] * 6
    assert [start.jump_mm for start in feed.monitor.starts] == [0.0] * 12


def test_a_jump_at_enable_is_flagged_and_recorded(feed) -> None:
    feed.feedback(START_UM)
    feed.enable()
    feed.cycle(0, [p + 5_000 for p in START_UM])
    assert feed.kinds() == ["velocity"] * 6
    assert "from the measured position" in feed.monitor.violations[0].message
    assert [start.jump_mm for start in feed.monitor.starts] == [5.0] * 6


def test_frames_an_actuator_would_reject_are_flagged(feed) -> None:
    can_id, payload = codec.encode_sync(3)
    feed.frame(can_id, payload[:-1] + bytes((payload[-1] ^ 0xFF,)))
    feed.frame(*codec.encode_setpoint_frame(1, 3, START_UM[:2])[:1], b"\x00" * 5)
    assert feed.kinds() == ["bad_crc", "undecodable"]


def test_late_and_partial_cycles_are_counted_not_flagged(feed) -> None:
    feed.cycle(0, START_UM)
    feed.cycle(1, START_UM, periods=3)  # the loop overran and skipped two deadlines
    feed.t_s += 1 / RATE_HZ
    feed.frame(*codec.encode_setpoint_frame(1, 2, START_UM[:2]))  # the rest of the cycle failed to send
    feed.frame(*codec.encode_sync(2))
    feed.frame(*codec.encode_sync(3))  # a bare SYNC
    feed.t_s += 10.0  # disabled for 10 s: the controller sends no cycle …
    feed.feedback(START_UM)
    feed.enable()
    feed.cycle(2, START_UM)  # … so the next session's first cycle, though it follows counter 1, is not late
    counts = feed.monitor.counts
    assert (counts["cycles"], counts["late_cycles"], counts["partial_cycles"], counts["bare_syncs"]) == (3, 1, 1, 1)
    assert feed.monitor.report().max_cycle_gap_s == pytest.approx(3 / RATE_HZ)
    assert feed.kinds() == []


@pytest.mark.parametrize("interface", IN_PROCESS_INTERFACES)
def test_the_reader_thread_sees_another_bus_on_the_channel(nominal, interface) -> None:
    channel = f"{interface}:monitor-thread-{next(_channels)}"
    with open_bus(channel) as sender, BusMonitor(channel, nominal, RATE_HZ) as monitor:
        for k in range(50):
            for can_id, payload in codec.encode_setpoints(k, START_UM):
                sender.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
        monitor.catch_up()
        assert monitor.counts["cycles"] == 50 and not monitor.violations


@pytest.mark.parametrize("interface", IN_PROCESS_INTERFACES)
def test_a_monitor_that_falls_behind_never_fails_the_senders(nominal, interface) -> None:
    """Its in-process bus queues without bound: the controller's sends cannot fail because
    the observer is slow (here: not reading at all)."""
    channel = f"{interface}:monitor-behind-{next(_channels)}"
    monitor = BusMonitor(channel, nominal, RATE_HZ)  # not started yet: reads nothing
    with open_bus(channel) as sender:
        for _ in range(IN_PROCESS_RX_QUEUE_SIZE + 10):
            sender.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))
    with monitor:
        monitor.catch_up()
    assert monitor.counts["frames"] == IN_PROCESS_RX_QUEUE_SIZE + 10
