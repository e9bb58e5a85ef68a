"""python-can's SocketCAN bus with one system call per frame on the paths every cycle takes.

Why: python-can's :class:`~can.interfaces.socketcan.SocketcanBus` spends three system calls
on each frame it sends or receives (``time.time()``, a ``select`` and the transfer) and two
on a receive that finds nothing. The loop sends four frames and reads six every cycle, and
the simulated actuators the reverse; where a system call is dear (a loaded host, user-mode
Linux, where each costs about 0.1 ms) that is most of a 4 ms cycle. A send that must not
wait (``timeout`` 0 or None: the set-points, SYNC, commands) and a receive that must not
wait (``timeout`` 0: draining what arrived) need only the transfer itself on a
non-blocking socket; everything else (a bounded wait, filtering, set-up, shutdown) is
python-can's own.

Frames are python-can's :class:`can.Message`, parsed by python-can (``capture_message``,
``build_can_frame``), with the kernel's receive timestamp as before. Errors are python-can's
:class:`can.CanOperationError`, carrying the OS error number: a full transmit queue is
``ENOBUFS`` or ``EAGAIN``, an interface gone down ``ENETDOWN``.
"""

from __future__ import annotations

import errno
import socket
from typing import Any

import can
from can.interfaces.socketcan.socketcan import SocketcanBus, build_can_frame, capture_message

_NOTHING_WAITING = frozenset({errno.EAGAIN, errno.EWOULDBLOCK})
SO_RCVBUFFORCE = 33
"""Linux's socket option (asm-generic/socket.h; Python's socket module does not name it): a
receive buffer beyond the kernel's ``rmem_max``, for root or CAP_NET_ADMIN."""


class LeanSocketcanBus(SocketcanBus):
    """A :class:`~can.interfaces.socketcan.SocketcanBus` on one CAN interface (``channel``
    must name it) whose non-waiting send and receive cost one system call each.

    ``receive_buffer_bytes``: the socket's receive buffer (None: the kernel's default, about
    270 classic frames, since the kernel charges about 768 bytes for each). Beyond the
    kernel's ``rmem_max`` it needs root or CAP_NET_ADMIN; without, the buffer is what
    ``rmem_max`` allows (:attr:`receive_buffer_bytes` says what was granted). A reader that
    may fall behind the bus for longer than the default holds (a simulator on a loaded host,
    a capture read afterwards) asks for more: frames that find the buffer full are lost.
    """

    def __init__(self, channel: str, receive_buffer_bytes: int | None = None, **options: Any) -> None:
        if not channel:
            raise ValueError("LeanSocketcanBus needs the interface's name (e.g. vcan0), not all interfaces")
        super().__init__(channel=channel, **options)
        # Non-blocking: a transfer that cannot happen now fails at once instead of waiting.
        # python-can's waiting paths select() first, so they are unchanged.
        self.socket.setblocking(False)
        if receive_buffer_bytes is not None:
            try:
                self.socket.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, receive_buffer_bytes)
            except PermissionError:
                self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_bytes)

    @property
    def receive_buffer_bytes(self) -> int:
        """The socket's receive buffer as the kernel reports it (twice what was granted)."""
        return self.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg``; with ``timeout`` 0 or None at once or not at all (one system call),
        else waiting up to ``timeout`` s for room (python-can's send).

        :raises can.CanOperationError: the frame was not sent (``error_code``: the OS error)
        """
        if timeout:
            super().send(msg, timeout)
            return
        data = build_can_frame(msg)
        try:
            sent = self.socket.send(data)
        except OSError as error:
            raise can.CanOperationError(f"Failed to transmit: {error.strerror}", error.errno) from error
        if sent != len(data):
            raise can.CanOperationError("Transmit buffer full")

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame that passes the filters, or None; with ``timeout`` 0 without
        waiting (one system call per frame read), else python-can's receive.

        :raises can.CanOperationError: the receive failed (``error_code``: the OS error)
        """
        if timeout != 0:
            return super().recv(timeout)
        while True:
            try:
                msg = capture_message(self.socket)
            except can.CanOperationError as error:
                if error.error_code in _NOTHING_WAITING:
                    return None
                raise
            msg.channel = self.channel
            if self._is_filtered or self._matches_filters(msg):
                return msg
