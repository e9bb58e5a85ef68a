"""LeanSocketcanBus's waiting send against a full transmit queue, on the host (no SocketCAN).

A CAN socket stays writable for select(2) while the interface's queue refuses frames with
ENOBUFS, and vcan has no queue to fill, so the socket here is a stand-in that refuses as a
full queue does.
"""

from __future__ import annotations

import errno
import os
import socket

import can
import pytest
from can.interfaces.socketcan.socketcan import build_can_frame

from firmware_proto import codec
from hexactl.adapters.can.socketcan_bus import LeanSocketcanBus

ESTOP = can.Message(arbitration_id=codec.FrameId.ESTOP, data=b"\x00", is_extended_id=False)
HANG_GUARD_S = 60.0  # long enough for any loaded host; the sends below end at once when they can


class QueueFullSocket:
    """Writable for select(2) (a datagram socket pair's end); its first ``full`` sends fail
    with ``error`` as SocketCAN's do while the interface's transmit queue is full."""

    def __init__(self, full: int, error: int = errno.ENOBUFS) -> None:
        self._end, self._peer = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.full = full
        self.error = error
        self.attempts = 0
        self.sent: list[bytes] = []

    def fileno(self) -> int:
        return self._end.fileno()

    def send(self, data: bytes) -> int:
        self.attempts += 1
        if self.full:
            self.full -= 1
            raise OSError(self.error, os.strerror(self.error))
        self.sent.append(data)
        return len(data)

    def close(self) -> None:
        self._end.close()
        self._peer.close()


@pytest.fixture
def make_bus():
    sockets = []

    def make(full: int, error: int = errno.ENOBUFS) -> tuple[LeanSocketcanBus, QueueFullSocket]:
        # Only what send reads: a real one needs AF_CAN, which a test host may not have.
        bus = LeanSocketcanBus.__new__(LeanSocketcanBus)
        bus.socket = fake = QueueFullSocket(full, error)
        bus.channel = "can0"
        bus._is_shutdown = True  # nothing of python-can's to shut down
        sockets.append(fake)
        return bus, fake

    yield make
    for fake in sockets:
        fake.close()


def test_a_waiting_send_waits_out_a_full_transmit_queue(make_bus):
    bus, fake = make_bus(full=3)
    bus.send(ESTOP, timeout=HANG_GUARD_S)
    assert fake.sent == [build_can_frame(ESTOP)] and fake.attempts == 4


def test_a_waiting_send_gives_up_at_its_timeout_with_the_os_error(make_bus):
    bus, fake = make_bus(full=10**9)
    with pytest.raises(can.CanOperationError) as failed:
        bus.send(ESTOP, timeout=0.001)
    assert failed.value.error_code == errno.ENOBUFS and fake.sent == []


def test_a_send_that_must_not_wait_fails_at_once_on_a_full_queue(make_bus):
    bus, fake = make_bus(full=1)
    with pytest.raises(can.CanOperationError) as failed:
        bus.send(ESTOP, timeout=0)
    assert failed.value.error_code == errno.ENOBUFS and fake.attempts == 1


def test_a_waiting_send_does_not_retry_an_interface_gone_down(make_bus):
    bus, fake = make_bus(full=1, error=errno.ENETDOWN)
    with pytest.raises(can.CanOperationError) as failed:
        bus.send(ESTOP, timeout=HANG_GUARD_S)
    assert failed.value.error_code == errno.ENETDOWN and fake.attempts == 1
