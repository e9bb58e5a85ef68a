"""A copy-free in-process CAN bus for python-can: the ``memory:NAME`` bus spec.

Every :class:`MemoryBus` opened on the same channel name in one process hears every frame
that another one sends, in the order sent, but not its own (python-can's ``virtual``
interface with its defaults). Unlike ``virtual``, which deep-copies each frame for each
receiver (several µs a copy, holding the GIL), :meth:`MemoryBus.send` stamps the message
once and puts *the same object* into each receiver's :class:`queue.SimpleQueue`. Hence two
rules for everyone on the bus:

* a sender hands its message over: it must not change or reuse it after ``send``;
* receivers share one object: they must not change a received message (copy it first).

The stamp is what a receiver of ``virtual`` sees: ``timestamp`` is the wall clock at the
send (``time.time()``, s), ``is_rx`` is True and ``channel`` is the name.

Frames are delivered at once and never lost silently. A receiver holding ``rx_queue_size``
unread frames gets no more; the send delivers to everyone else and then raises
:class:`can.CanOperationError`, as ``virtual`` does when a receive queue is full. The bus
has no error states: :attr:`~can.BusABC.state` is always ``ACTIVE``. Filters are
python-can's software filters (:meth:`~can.BusABC.set_filters`).
"""

from __future__ import annotations

import queue
import threading
import time

import can
from can.typechecking import CanFilters


class _Channel:
    """The buses open on one name. ``buses`` is replaced, never changed in place, so that a
    send can iterate over it without taking the lock."""

    __slots__ = ("buses",)

    def __init__(self) -> None:
        self.buses: tuple[MemoryBus, ...] = ()


_channels: dict[str, _Channel] = {}
_channels_lock = threading.Lock()  # guards _channels and every _Channel.buses replacement


class MemoryBus(can.BusABC):
    """One node on the in-process bus ``channel``.

    :param channel: the bus's name; every bus opened on it in this process hears this one
    :param rx_queue_size: unread frames this bus keeps before senders get errors (0: no
        bound). Checked before each put without a lock, so concurrent senders may overshoot
        it by one frame each.
    :param can_filters: python-can filters (see :meth:`~can.BusABC.set_filters`), applied
        in software on receive
    :raises ValueError: for a negative ``rx_queue_size`` or malformed filters
    """

    def __init__(self, channel: str, rx_queue_size: int = 0, can_filters: CanFilters | None = None) -> None:
        if rx_queue_size < 0:
            raise ValueError(f"rx_queue_size must be ≥ 0, got {rx_queue_size}")
        super().__init__(channel, can_filters=can_filters)
        self.channel_info = f"memory bus {channel!r}"
        self._name = channel
        self._rx_queue_size = rx_queue_size
        self._queue: queue.SimpleQueue[can.Message | None] = queue.SimpleQueue()
        with _channels_lock:
            self._channel = _channels.setdefault(channel, _Channel())
            self._channel.buses += (self,)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Stamp ``msg`` and deliver it to every other bus on the name; never waits.

        :param msg: handed over: not to be changed or reused afterwards
        :param timeout: accepted for the interface and ignored: a receiver whose queue is
            full has stopped reading, and waiting for it would only stall the sender
        :raises can.CanOperationError: if this bus is shut down ("closed bus"), or if some
            receiver's queue was full (the others got the frame)
        """
        if self._is_shutdown:
            raise self._closed()
        msg.timestamp = time.time()
        msg.is_rx = True
        msg.channel = self._name
        full = 0
        for bus in self._channel.buses:
            if bus is self:
                continue
            bound = bus._rx_queue_size
            if bound and bus._queue.qsize() >= bound:
                full += 1
            else:
                bus._queue.put(msg)
        if full:
            raise can.CanOperationError(f"{self.channel_info}: {full} receiver(s) full, frame not delivered to them")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        """The next frame, waiting at most ``timeout`` s (None: for ever); (None, False) if
        none came. Filtering is left to :meth:`~can.BusABC.recv`.

        :raises can.CanOperationError: if this bus is shut down ("closed bus")
        """
        if self._is_shutdown:
            raise self._closed()
        try:
            return self._queue.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def shutdown(self) -> None:
        """Leave the bus: senders no longer deliver here, and this bus's send and receive
        raise. Safe to call more than once."""
        if self._is_shutdown:
            return
        super().shutdown()
        with _channels_lock:
            self._channel.buses = tuple(bus for bus in self._channel.buses if bus is not self)
            if not self._channel.buses:
                del _channels[self._name]
        # Wakes a receiver blocked without a timeout: recv() then finds the bus closed.
        self._queue.put(None)

    def _closed(self) -> can.CanOperationError:
        # "closed bus", as python-can's own buses say: transport.bus_state_after_send_error reads it.
        return can.CanOperationError(f"{self.channel_info}: cannot operate on a closed bus")
