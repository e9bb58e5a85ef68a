"""Which CAN bus to use: spec strings, opening a python-can bus, and the bus's error state.

A *bus spec* names an interface and a channel, ``INTERFACE:CHANNEL``:

============================  =================================================================
``socketcan:can0``            a real SocketCAN interface (Linux), e.g. a USB or PCIe adapter
``socketcan:vcan0``           the kernel's virtual CAN (needs ``vcan``; see tools/uml_vcan.py)
``memory:NAME``               an in-process bus that does not copy frames
                              (:mod:`hexactl.adapters.can.memory_bus`): every bus opened on
                              ``NAME`` in the same process hears the others' frames, and no one
                              may change a frame sent or received (the built-in simulator's)
``virtual:NAME``              python-can's in-process bus: the same, but every receiver gets
                              its own copy of each frame
============================  =================================================================

Everything below the spec is python-can: :func:`open_bus` returns a :class:`can.BusABC`, for
SocketCAN python-can's own bus with a leaner non-waiting send and receive
(:mod:`hexactl.adapters.can.socketcan_bus`).
"""

from __future__ import annotations

import errno
from dataclasses import dataclass
from typing import Any

import can

from hexactl.adapters.can.memory_bus import MemoryBus
from hexactl.adapters.can.socketcan_bus import LeanSocketcanBus
from hexactl.control.hardware import BusState

IN_PROCESS_INTERFACES = ("memory", "virtual")
"""The interfaces whose buses live in this process: they take ``rx_queue_size``."""

INTERFACES = ("socketcan", *IN_PROCESS_INTERFACES)
"""The interfaces a spec may name: python-can's, and ``memory`` (:class:`MemoryBus`)."""

IN_PROCESS_RX_QUEUE_SIZE = 10_000
"""Frames a ``memory:`` or ``virtual:`` bus keeps unread before senders get errors. Bounded
so that a bus nobody reads (a spy left open in a test, a stalled loop) cannot grow memory
without limit."""


class BusSpecError(ValueError):
    """A bus spec that is not ``INTERFACE:CHANNEL`` with a known interface."""


@dataclass(frozen=True, slots=True)
class BusSpec:
    """A parsed bus spec: python-can's ``interface`` and ``channel``."""

    interface: str
    channel: str

    def __str__(self) -> str:
        return f"{self.interface}:{self.channel}"


def in_process_note(spec: BusSpec) -> str | None:
    """What a command given an in-process bus should say (None for one that crosses
    processes): no actuator or simulator in another process can be on it."""
    if spec.interface not in IN_PROCESS_INTERFACES:
        return None
    return (f"{spec} is an in-process bus: only this process hears it, so nothing in another process (actuators, "
            "hexactl sim-actuators, another service) will answer on it; between processes use socketcan:CHANNEL "
            "(a virtual one: sudo ip link add vcan0 type vcan && sudo ip link set vcan0 up; docs/can.md)")


def parse_bus_spec(spec: str) -> BusSpec:
    """Parse ``socketcan:CHANNEL``, ``memory:NAME`` or ``virtual:NAME``.

    :raises BusSpecError: for anything else (the message says what is accepted)
    """
    interface, separator, channel = spec.strip().partition(":")
    if not separator or not channel or interface not in INTERFACES:
        raise BusSpecError(
            f"bus spec {spec!r}: expected socketcan:CHANNEL (e.g. socketcan:can0, socketcan:vcan0), "
            "memory:NAME or virtual:NAME"
        )
    return BusSpec(interface, channel)


def open_bus(spec: str | BusSpec, **options: Any) -> can.BusABC:
    """Open the bus named by ``spec``; ``options`` go unchanged to :class:`can.Bus`, for
    ``socketcan:`` to :class:`LeanSocketcanBus` (python-can's SocketCAN bus) and for
    ``memory:`` to :class:`MemoryBus`.

    In-process buses get a bounded receive queue (:data:`IN_PROCESS_RX_QUEUE_SIZE`) unless
    ``rx_queue_size`` is given (0: unbounded).

    :raises BusSpecError: for a malformed spec
    :raises can.CanError: if python-can cannot open it (e.g. ``can.CanInitializationError``
        for a missing SocketCAN interface)
    :raises OSError: for operating-system errors python-can passes through (for a missing
        SocketCAN interface or a kernel without SocketCAN, saying how to bring it up)
    :raises TypeError: for an option a ``memory:`` bus does not take (``rx_queue_size``,
        ``can_filters``)
    """
    parsed = parse_bus_spec(spec) if isinstance(spec, str) else spec
    if parsed.interface in IN_PROCESS_INTERFACES:
        options.setdefault("rx_queue_size", IN_PROCESS_RX_QUEUE_SIZE)
    if parsed.interface == "memory":
        # Constructed here, not registered as a python-can "can.interface" entry point: an
        # entry point works only once the package's metadata is reinstalled, and can.Bus
        # would also merge in python-can's configuration files and CAN_* environment variables.
        return MemoryBus(parsed.channel, **options)
    if parsed.interface == "socketcan":
        try:
            return LeanSocketcanBus(parsed.channel, **options)
        except OSError as error:
            raise _socketcan_open_error(parsed.channel, error) from error
    return can.Bus(interface=parsed.interface, channel=parsed.channel, **options)


def _socketcan_open_error(channel: str, error: OSError) -> OSError:
    """``error`` from opening a SocketCAN bus, with what to do when the cause is the usual one."""
    if error.errno == errno.ENODEV:
        create = (f"ip link add dev {channel} type vcan" if channel.startswith("vcan")
                  else f"ip link set {channel} type can bitrate 1000000")  # the protocol's bit rate
        hint = (f"there is no CAN interface {channel!r} (ip -details link show lists them); "
                f"bring it up with: {create} && ip link set {channel} up")
    elif error.errno == errno.EAFNOSUPPORT:
        hint = "this kernel has no SocketCAN: load it with modprobe can_raw (and your adapter's driver)"
    else:
        return error
    return OSError(error.errno, f"{error.strerror}: {hint}")


# SocketCAN error-frame bits (linux/can/error.h): the identifier says the error class,
# data[1] details controller problems.
_CAN_ERR_CRTL = 0x004
_CAN_ERR_BUSOFF = 0x040
_CAN_ERR_RESTARTED = 0x100
_CAN_ERR_CRTL_RX_WARNING = 0x04
_CAN_ERR_CRTL_TX_WARNING = 0x08
_CAN_ERR_CRTL_RX_PASSIVE = 0x10
_CAN_ERR_CRTL_TX_PASSIVE = 0x20
_CAN_ERR_CRTL_ACTIVE = 0x40


def bus_state_from_error_frame(message: can.Message) -> BusState | None:
    """The bus state a SocketCAN error frame announces, or None if it announces none.

    python-can delivers the kernel's error frames as messages with ``is_error_frame``;
    only bus-off, restart and controller warning/passive/active changes move the state.
    """
    error_class = message.arbitration_id
    if error_class & _CAN_ERR_BUSOFF:
        return BusState.BUS_OFF
    if error_class & _CAN_ERR_RESTARTED:
        return BusState.ACTIVE
    if error_class & _CAN_ERR_CRTL and len(message.data) > 1:
        detail = message.data[1]
        if detail & (_CAN_ERR_CRTL_RX_PASSIVE | _CAN_ERR_CRTL_TX_PASSIVE):
            return BusState.PASSIVE
        if detail & (_CAN_ERR_CRTL_RX_WARNING | _CAN_ERR_CRTL_TX_WARNING):
            return BusState.WARNING
        if detail & _CAN_ERR_CRTL_ACTIVE:
            return BusState.ACTIVE
    return None


_DOWN_ERRNOS = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO, errno.EBADF})


def bus_state_after_send_error(error: Exception, current: BusState) -> BusState:
    """The bus state implied by a failed send.

    ENETDOWN/ENODEV (interface down or removed) and a closed bus mean ``DOWN``; a full
    transmit queue (ENOBUFS, "Transmit buffer full") says nothing new about the bus.
    python-can has no error type for a closed bus: its buses raise ``CanOperationError``
    saying "closed bus" (``can/interfaces/virtual.py``), and so does :class:`MemoryBus`.
    """
    code = getattr(error, "error_code", None)
    if code in _DOWN_ERRNOS or (isinstance(error, can.CanOperationError) and "closed bus" in str(error)):
        return BusState.DOWN
    return current
