"""Smoke tests proving real SocketCAN on vcan0 works (inside UML or on a box with vcan0).

Collected only where /sys/class/net/vcan0 exists (tests/conftest.py); on other
hosts tests/test_vcan_in_uml.py runs them inside user-mode Linux.
"""

import subprocess
import sys
import textwrap
import time

import can
import pytest

from hexactl.adapters.can.socketcan_bus import LeanSocketcanBus

pytestmark = pytest.mark.vcan

CHANNEL = "vcan0"
RECV_TIMEOUT = 2.0


def open_bus(**kwargs) -> can.BusABC:
    return can.Bus(interface="socketcan", channel=CHANNEL, **kwargs)


def recv_matching(bus: can.BusABC, arbitration_id: int, timeout: float = RECV_TIMEOUT):
    """Next frame with ``arbitration_id`` (ignoring others), or None on timeout."""
    end = time.monotonic() + timeout
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(timeout=left)
        if msg is not None and msg.arbitration_id == arbitration_id:
            return msg
    return None


def test_vcan0_is_a_real_can_interface():
    with open("/sys/class/net/vcan0/type") as f:
        assert f.read().strip() == "280"  # ARPHRD_CAN
    with open("/sys/class/net/vcan0/flags") as f:
        assert int(f.read().strip(), 16) & 0x1  # IFF_UP


def test_frame_between_two_buses():
    with open_bus() as tx, open_bus() as rx:
        sent = [
            can.Message(arbitration_id=0x123, data=bytes([1, 2, 3, 4]), is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDE0, data=b"\xde\xad\xbe\xef\x00\x11\x22\x33",
                        is_extended_id=True),
            can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False),
        ]
        for msg in sent:
            tx.send(msg)
        for msg in sent:
            got = rx.recv(timeout=RECV_TIMEOUT)
            assert got is not None, f"no frame received for id {msg.arbitration_id:#x}"
            assert got.arbitration_id == msg.arbitration_id
            assert got.is_extended_id == msg.is_extended_id
            assert bytes(got.data) == bytes(msg.data)
            assert got.dlc == len(msg.data)
            assert got.channel == CHANNEL
        # the sender does not see its own frames (receive_own_messages off)
        assert tx.recv(timeout=0.2) is None


def test_kernel_can_filter():
    flt = [{"can_id": 0x120, "can_mask": 0x7F0, "extended": False}]  # ids 0x120..0x12F
    with open_bus() as tx, open_bus(can_filters=flt) as rx:
        for can_id in (0x100, 0x121, 0x130, 0x12F, 0x220):
            tx.send(can.Message(arbitration_id=can_id, data=[can_id & 0xFF], is_extended_id=False))
        got = []
        while (msg := rx.recv(timeout=0.5)) is not None:
            got.append((msg.arbitration_id, bytes(msg.data)))
        assert got == [(0x121, b"\x21"), (0x12F, b"\x2f")]


ECHO_CHILD = textwrap.dedent(
    """
    import sys, time, can
    bus = can.Bus(interface="socketcan", channel="vcan0")
    print("READY", flush=True)
    end = time.monotonic() + 30
    n = 0
    try:
        while time.monotonic() < end:
            msg = bus.recv(timeout=0.5)
            if msg is None:
                continue
            if msg.arbitration_id == 0x7FF:  # stop request
                break
            if msg.arbitration_id % 2 == 0:  # echo even ids back as id+1
                bus.send(can.Message(arbitration_id=msg.arbitration_id + 1, data=msg.data,
                                     is_extended_id=msg.is_extended_id))
                n += 1
    finally:
        bus.shutdown()
    print(f"ECHOED {n}", flush=True)
    """
)


def test_echo_across_processes():
    child = subprocess.Popen([sys.executable, "-c", ECHO_CHILD], stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "READY", child.stderr.read()
        with open_bus() as bus:
            for i, can_id in enumerate((0x100, 0x202, 0x3FE)):
                payload = bytes([i, 0xA5, 0x5A, can_id & 0xFF])
                bus.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
                reply = recv_matching(bus, can_id + 1)
                assert reply is not None, f"no echo for {can_id:#x} from the child process"
                assert bytes(reply.data) == payload
            bus.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))
        out, err = child.communicate(timeout=10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == 0, err
    assert out.strip() == "ECHOED 3"


def test_the_lean_bus_sends_and_receives_what_python_can_does():
    """hexactl's SocketCAN bus (one system call per non-waiting transfer) against python-can's."""
    frames = [
        can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False),
        can.Message(arbitration_id=0x1ABCDE0, data=b"\x01\x02", is_extended_id=True),
        can.Message(arbitration_id=0x080, data=b"", is_extended_id=False),
    ]
    with LeanSocketcanBus(CHANNEL) as lean, open_bus() as plain:
        assert lean.recv(0.0) is None  # nothing waiting: at once
        before = time.time()
        for frame in frames:
            lean.send(frame, 0.0)
        for frame in frames:
            got = plain.recv(timeout=RECV_TIMEOUT)
            assert (got.arbitration_id, got.is_extended_id, bytes(got.data)) == (
                frame.arbitration_id, frame.is_extended_id, bytes(frame.data))
        for frame in frames:
            plain.send(frame)
        received = []
        deadline = time.monotonic() + RECV_TIMEOUT
        while len(received) < len(frames) and time.monotonic() < deadline:
            if (got := lean.recv(0.0)) is not None:
                received.append(got)
        assert [(m.arbitration_id, m.is_extended_id, bytes(m.data), m.channel) for m in received] == [
            (f.arbitration_id, f.is_extended_id, bytes(f.data), CHANNEL) for f in frames]
        assert all(before <= m.timestamp <= time.time() for m in received)  # the kernel's receive time
        assert lean.recv(0.0) is None
        lean.send(frames[0], timeout=0.5)  # a bounded wait for room: python-can's own path
        assert plain.recv(timeout=RECV_TIMEOUT).arbitration_id == frames[0].arbitration_id


def test_the_lean_bus_keeps_the_kernel_filter_when_draining():
    flt = [{"can_id": 0x120, "can_mask": 0x7F0, "extended": False}]
    with open_bus() as tx, LeanSocketcanBus(CHANNEL, can_filters=flt) as rx:
        for can_id in (0x100, 0x121, 0x130, 0x12F):
            tx.send(can.Message(arbitration_id=can_id, data=[can_id & 0xFF], is_extended_id=False))
        assert rx.recv(timeout=RECV_TIMEOUT).arbitration_id == 0x121  # waits: python-can's path
        deadline = time.monotonic() + RECV_TIMEOUT
        while (msg := rx.recv(0.0)) is None and time.monotonic() < deadline:
            pass
        assert msg.arbitration_id == 0x12F
        assert rx.recv(0.0) is None


def test_the_lean_bus_sends_a_batch_in_order_in_one_system_call_per_sixteen(monkeypatch):
    from hexactl.adapters.can import socketcan_bus

    calls = []
    real = socketcan_bus._sendmmsg

    def counted(fd, headers, count, flags):
        calls.append(count)
        return real(fd, headers, count, flags)

    monkeypatch.setattr(socketcan_bus, "_sendmmsg", counted)
    frames = [can.Message(arbitration_id=0x200 + i, data=bytes([i] * (i % 9)), is_extended_id=False) for i in range(20)]
    frames[3] = can.Message(arbitration_id=0x1ABCDE0, data=b"\x01\x02", is_extended_id=True)
    with LeanSocketcanBus(CHANNEL) as lean, open_bus() as plain:
        lean.send_batch(frames)
        received = [plain.recv(timeout=RECV_TIMEOUT) for _ in frames]
        assert plain.recv(timeout=0.2) is None
    assert calls == [16, 4]
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in received] == [
        (f.arbitration_id, f.is_extended_id, bytes(f.data)) for f in frames]


def test_a_batch_the_kernel_takes_in_part_is_finished_frame_by_frame(monkeypatch):
    """sendmmsg(2) stops at a frame it cannot send; the bus sends that one alone (which says
    why, or sends it) and goes on, so the order holds."""
    from hexactl.adapters.can import socketcan_bus

    real = socketcan_bus._sendmmsg
    monkeypatch.setattr(socketcan_bus, "_sendmmsg", lambda fd, headers, count, flags: real(fd, headers, min(count, 2), flags))
    frames = [can.Message(arbitration_id=0x300 + i, data=bytes([i]), is_extended_id=False) for i in range(7)]
    with LeanSocketcanBus(CHANNEL) as lean, open_bus() as plain:
        lean.send_batch(frames)
        received = [plain.recv(timeout=RECV_TIMEOUT) for _ in frames]
        assert plain.recv(timeout=0.2) is None
    assert [m.arbitration_id for m in received] == [f.arbitration_id for f in frames]


def test_a_batch_that_cannot_be_sent_says_why_and_how_many_went():
    from hexactl.adapters.can.socketcan_bus import BatchSendError

    lean = LeanSocketcanBus(CHANNEL)
    lean.shutdown()  # its socket closed: every send fails
    with pytest.raises(BatchSendError) as caught:
        lean.send_batch([can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False)])
    assert caught.value.sent == 0 and caught.value.error_code is not None


def test_the_lean_bus_reads_what_arrived_in_order_whichever_way_it_is_asked():
    """More frames than one read takes, read without waiting and waiting, mixed: every one
    once, in order, with the kernel's receive time; then nothing."""
    frames = [can.Message(arbitration_id=0x400 + i, data=bytes([i] * (i % 9)), is_extended_id=bool(i % 5 == 0))
              for i in range(37)]  # fmt: skip
    with open_bus() as plain, LeanSocketcanBus(CHANNEL) as lean:
        before = time.time()
        for frame in frames:
            plain.send(frame)
        received = []
        deadline = time.monotonic() + RECV_TIMEOUT
        while len(received) < len(frames) and time.monotonic() < deadline:
            got = lean.recv(0.0) if len(received) % 3 else lean.recv(timeout=RECV_TIMEOUT)
            if got is not None:
                received.append(got)
        assert [(m.arbitration_id, m.is_extended_id, bytes(m.data), m.channel) for m in received] == [
            (f.arbitration_id, f.is_extended_id, bytes(f.data), CHANNEL) for f in frames]
        assert all(before <= m.timestamp <= time.time() for m in received)
        assert lean.recv(0.0) is None and lean.recv(timeout=0.1) is None
        plain.send(frames[0])  # after a None, the next read looks again
        deadline = time.monotonic() + RECV_TIMEOUT
        while (got := lean.recv(0.0)) is None and time.monotonic() < deadline:
            pass
        assert got.arbitration_id == frames[0].arbitration_id
