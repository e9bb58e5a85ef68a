"""The copy-free in-process bus (``memory:NAME``): who hears what, the same object for every
receiver, filters, the receive bound, shutdown, timeouts, threads; a model-based property
test of delivery and the bound; and the link's reaction to a full receiver, the same as on
``virtual:``. Send cost beside ``virtual:`` with ``--benchmark-enable``."""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from collections.abc import Iterator

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.can.link import CanActuatorLink
from hexactl.adapters.can.memory_bus import MemoryBus
from hexactl.adapters.can.transport import IN_PROCESS_RX_QUEUE_SIZE, bus_state_after_send_error, open_bus
from hexactl.control.hardware import BusState

SETPOINTS_MM = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0]
_names = itertools.count()


def _name() -> str:
    return f"memory-test-{next(_names)}"


def _frame(can_id: int = 0x101, data: bytes = b"\x01\x02") -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


@pytest.fixture
def buses() -> Iterator[list[MemoryBus]]:
    """Three buses on one fresh name; shut down afterwards."""
    name = _name()
    opened = [MemoryBus(name) for _ in range(3)]
    yield opened
    for bus in opened:
        bus.shutdown()


def test_every_other_bus_hears_the_same_stamped_object_and_the_sender_does_not():
    name = _name()
    sender, first, second = (MemoryBus(name) for _ in range(3))
    try:
        message = _frame()
        before = time.time()
        sender.send(message)
        assert first.recv(0.0) is message
        assert second.recv(0.0) is message
        assert sender.recv(0.0) is None
        assert before <= message.timestamp <= time.time()
        assert message.is_rx
        assert message.channel == name
    finally:
        for bus in (sender, first, second):
            bus.shutdown()


def test_frames_arrive_in_the_order_sent_from_every_sender(buses):
    a, b, listener = buses
    sent = [_frame(0x100 + i) for i in range(6)]
    for i, message in enumerate(sent):
        (a if i % 2 else b).send(message)
    assert [listener.recv(0.0) for _ in sent] == sent
    assert listener.recv(0.0) is None


def test_names_are_separate_buses():
    here, there = MemoryBus(_name()), MemoryBus(_name())
    try:
        here.send(_frame())
        assert there.recv(0.0) is None
    finally:
        here.shutdown()
        there.shutdown()


def test_filters_from_the_constructor_and_set_filters():
    name = _name()
    sender = MemoryBus(name)
    only_0x10 = MemoryBus(name, can_filters=[{"can_id": 0x10, "can_mask": 0x7FF, "extended": False}])
    try:
        for can_id in (0x11, 0x10, 0x12):
            sender.send(_frame(can_id))
        # python-can's recv skips non-matching frames only while time is left: not with timeout 0.
        assert only_0x10.recv(1.0).arbitration_id == 0x10
        assert only_0x10.recv(0.01) is None
        only_0x10.set_filters([{"can_id": 0x20, "can_mask": 0x7F0}])
        sender.send(_frame(0x10))
        sender.send(_frame(0x2A))
        assert only_0x10.recv(1.0).arbitration_id == 0x2A
    finally:
        sender.shutdown()
        only_0x10.shutdown()


def test_a_full_receiver_fails_the_send_the_others_still_get_the_frame():
    name = _name()
    sender, bounded, unbounded = MemoryBus(name), MemoryBus(name, rx_queue_size=2), MemoryBus(name)
    try:
        sender.send(_frame())
        sender.send(_frame())
        with pytest.raises(can.CanOperationError, match=f"memory bus '{name}'.*full") as raised:
            sender.send(_frame(0x333))
        assert "closed bus" not in str(raised.value)  # a full receiver does not take the bus down
        assert bus_state_after_send_error(raised.value, BusState.ACTIVE) is BusState.ACTIVE
        assert [unbounded.recv(0.0).arbitration_id for _ in range(3)] == [0x101, 0x101, 0x333]
        assert bounded.recv(0.0) is not None
        sender.send(_frame())  # room again
    finally:
        for bus in (sender, bounded, unbounded):
            bus.shutdown()


def test_shutdown_leaves_the_bus_and_closes_this_one(buses):
    sender, leaving, staying = buses
    leaving.shutdown()
    leaving.shutdown()  # idempotent
    sender.send(_frame())  # nobody delivers to the bus that left
    assert staying.recv(0.0) is not None
    for operation in (lambda: leaving.send(_frame()), lambda: leaving.recv(0.0)):
        with pytest.raises(can.CanOperationError, match="closed bus") as raised:
            operation()
        assert bus_state_after_send_error(raised.value, BusState.ACTIVE) is BusState.DOWN


def test_shutdown_wakes_a_receiver_waiting_without_timeout():
    bus = MemoryBus(_name())
    outcome: list[BaseException] = []

    def wait_for_ever() -> None:
        try:
            bus.recv()
        except can.CanOperationError as error:
            outcome.append(error)

    waiter = threading.Thread(target=wait_for_ever)
    waiter.start()
    time.sleep(0.05)
    bus.shutdown()
    waiter.join(5.0)
    assert not waiter.is_alive()
    assert outcome and "closed bus" in str(outcome[0])


def test_receive_times_out_with_none(buses):
    """recv(timeout) waits at least that long, then returns None. How much longer is the
    host's scheduling, not the bus's: only that it returns at all is bounded here."""
    waited: list[tuple[object, float]] = []

    def receive() -> None:
        start = time.monotonic()
        waited.append((buses[0].recv(0.05), time.monotonic() - start))

    receiver = threading.Thread(target=receive)
    receiver.start()
    receiver.join(60.0)
    assert not receiver.is_alive(), "recv(0.05) did not return"
    (received, seconds), = waited
    assert received is None and seconds >= 0.04
    assert buses[0].recv(0.0) is None


def test_a_waiting_receiver_gets_a_frame_sent_meanwhile(buses):
    sender, receiver, _ = buses
    message = _frame()
    threading.Timer(0.02, sender.send, (message,)).start()
    assert receiver.recv(5.0) is message


def test_state_is_active_and_bad_options_are_refused(buses):
    assert buses[0].state is can.BusState.ACTIVE
    with pytest.raises(ValueError, match="rx_queue_size"):
        MemoryBus(_name(), rx_queue_size=-1)
    with pytest.raises(TypeError):
        open_bus(f"memory:{_name()}", receive_own_messages=True)


def test_open_bus_bounds_memory_buses_unless_told():
    name = _name()
    bounded, unbounded = open_bus(f"memory:{name}"), open_bus(f"memory:{name}", rx_queue_size=0)
    try:
        assert isinstance(bounded, MemoryBus)
        for _ in range(IN_PROCESS_RX_QUEUE_SIZE):
            unbounded.send(_frame())
            bounded.send(_frame())
        with pytest.raises(can.CanOperationError, match="full"):
            unbounded.send(_frame())
        bounded.send(_frame())
    finally:
        bounded.shutdown()
        unbounded.shutdown()


def test_many_threads_every_receiver_gets_every_other_senders_frames_in_order():
    name = _name()
    senders, frames_each = 4, 500
    buses = [MemoryBus(name) for _ in range(senders)]
    listener = MemoryBus(name)
    received: dict[int, list[tuple[int, int]]] = {}

    def run(index: int) -> None:
        bus = buses[index]
        for n in range(frames_each):
            bus.send(_frame(0x100 + index, n.to_bytes(2, "little")))
        got = []
        while len(got) < (senders - 1) * frames_each:
            message = bus.recv(5.0)
            assert message is not None
            got.append((message.arbitration_id - 0x100, int.from_bytes(message.data, "little")))
        received[index] = got

    threads = [threading.Thread(target=run, args=(i,)) for i in range(senders)]
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(30.0)
        heard = [listener.recv(0.0) for _ in range(senders * frames_each)]
        assert listener.recv(0.0) is None
        assert None not in heard
        for index in range(senders):
            others = sorted(received[index])
            assert others == sorted((i, n) for i in range(senders) if i != index for n in range(frames_each))
            for source in range(senders):  # per sender, the order sent
                from_source = [n for i, n in received[index] if i == source]
                assert from_source == sorted(from_source)
    finally:
        for bus in (*buses, listener):
            bus.shutdown()


_operations = st.lists(st.tuples(st.sampled_from(("send", "recv")), st.integers(0, 2)), max_size=60)


@settings(max_examples=200, deadline=None)
@given(operations=_operations, bounds=st.lists(st.integers(0, 3), min_size=3, max_size=3))
def test_delivery_and_the_bound_follow_a_model(operations, bounds):
    """Any interleaving of sends and receives on three buses with small bounds (0: none)
    behaves like per-receiver FIFO queues that refuse frames once full."""
    name = _name()
    buses = [MemoryBus(name, rx_queue_size=bound) for bound in bounds]
    model: list[deque[can.Message]] = [deque() for _ in buses]
    try:
        for operation, index in operations:
            if operation == "recv":
                expected = model[index].popleft() if model[index] else None
                assert buses[index].recv(0.0) is expected
                continue
            message = _frame()
            full = False
            for other, queue in enumerate(model):
                if other != index:
                    if bounds[other] and len(queue) >= bounds[other]:
                        full = True
                    else:
                        queue.append(message)
            if full:
                with pytest.raises(can.CanOperationError):
                    buses[index].send(message)
            else:
                buses[index].send(message)
    finally:
        for bus in buses:
            bus.shutdown()


@pytest.mark.parametrize("interface", ["memory", "virtual"])
def test_the_link_counts_a_full_receiver_as_a_failed_send_and_stays_active(interface):
    spec = f"{interface}:{_name()}"
    link = CanActuatorLink.open(spec)
    analyser = open_bus(spec, rx_queue_size=1)  # full after the first frame, never read
    try:
        assert not link.send_setpoints(0, SETPOINTS_MM)
        health = link.link_health()
        assert health.send_failures == 1  # the rest of the cycle is dropped, not sent
        assert health.bus_state is BusState.ACTIVE
        assert analyser.recv(0.0) is not None  # the first SETPOINT frame
        assert analyser.recv(0.0) is None
    finally:
        link.close()
        analyser.shutdown()


@pytest.mark.parametrize("interface", ["memory", "virtual"])
def test_send_cost_to_two_receivers(benchmark, interface):
    """One 8-byte frame sent to two receivers and read by both: what a loop's frame costs
    with the simulated actuators and a bus monitor listening."""
    spec = f"{interface}:{_name()}"
    sender, receivers = open_bus(spec), [open_bus(spec) for _ in range(2)]

    def send_and_read() -> None:
        sender.send(_frame(0x101, bytes(8)), 0.0)
        for receiver in receivers:
            receiver.recv(0.0)

    try:
        benchmark.pedantic(send_and_read, rounds=20_000 if benchmark.enabled else 3, warmup_rounds=100)
        assert all(receiver.recv(0.0) is None for receiver in receivers)
    finally:
        for bus in (sender, *receivers):
            bus.shutdown()
