"""python-can's SocketCAN bus with as few system calls as the cycle's frames allow.

Why: python-can's :class:`~can.interfaces.socketcan.SocketcanBus` spends three system calls
on each frame it sends (``time.time()``, a ``select`` and the transfer) and four on each it
receives (Python's ``recvmsg`` on a CAN socket also asks the interface's name with an
``ioctl``), two on a receive that finds nothing. The loop sends four frames and reads six
every cycle, and the simulated actuators the reverse; where a system call is dear (a loaded
host, user-mode Linux, where each costs about 0.1 ms) that was most of a 4 ms cycle. Here:

- frames that go out together (a cycle's set-points and SYNC, the actuators' answers to one
  SYNC) go in one ``sendmmsg(2)`` (:meth:`LeanSocketcanBus.send_batch`), and a reader of
  higher priority is woken once for the lot instead of once per frame; a single frame that
  must not wait is one ``send(2)``;
- what has arrived is read in one ``recvmmsg(2)`` (up to :data:`BATCH_FRAMES`, without the
  interface's name, with the kernel's receive timestamps) and handed out frame by frame.

Python's socket module has neither call, hence :mod:`ctypes`. A send's bounded wait also
waits out a full transmit queue (ENOBUFS), which python-can's fails on at once. Filtering,
set-up and shutdown are python-can's own, and frames are python-can's :class:`can.Message`,
parsed by python-can (``capture_message``, ``build_can_frame``). Errors are python-can's
:class:`can.CanOperationError`, carrying the OS error number: a full transmit queue is
``ENOBUFS`` or ``EAGAIN``, an interface gone down ``ENETDOWN``.
"""

from __future__ import annotations

import ctypes
import errno
import os
import select
import socket
import struct
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import can
from can.interfaces.socketcan.constants import CANFD_MTU
from can.interfaces.socketcan.socketcan import SocketcanBus, build_can_frame, capture_message

_NOTHING_WAITING = frozenset({errno.EAGAIN, errno.EWOULDBLOCK})
_QUEUE_FULL = frozenset({errno.ENOBUFS, errno.EAGAIN, errno.EWOULDBLOCK})
QUEUE_FULL_POLL_S = 0.0001
"""How often a send with a timeout tries again while the transmit queue is full: about
one classic frame's time on a 1 Mbit/s bus. (No poll(2) event announces room in an
interface's queue: a CAN socket stays writable while the queue refuses with ENOBUFS.)"""
SO_RCVBUFFORCE = 33
"""Linux's socket option (asm-generic/socket.h; Python's socket module does not name it): a
receive buffer beyond the kernel's ``rmem_max``, for root or CAP_NET_ADMIN."""


class _IoVec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class _MsgHdr(ctypes.Structure):
    _fields_ = [("msg_name", ctypes.c_void_p), ("msg_namelen", ctypes.c_uint32),
                ("msg_iov", ctypes.POINTER(_IoVec)), ("msg_iovlen", ctypes.c_size_t),
                ("msg_control", ctypes.c_void_p), ("msg_controllen", ctypes.c_size_t),
                ("msg_flags", ctypes.c_int)]  # fmt: skip


class _MMsgHdr(ctypes.Structure):
    _fields_ = [("msg_hdr", _MsgHdr), ("msg_len", ctypes.c_uint)]


_libc = ctypes.CDLL(None, use_errno=True)
_sendmmsg = _libc.sendmmsg
_sendmmsg.argtypes = [ctypes.c_int, ctypes.POINTER(_MMsgHdr), ctypes.c_uint, ctypes.c_int]
_sendmmsg.restype = ctypes.c_int
_recvmmsg = _libc.recvmmsg
_recvmmsg.argtypes = [ctypes.c_int, ctypes.POINTER(_MMsgHdr), ctypes.c_uint, ctypes.c_int, ctypes.c_void_p]
_recvmmsg.restype = ctypes.c_int
_MSG_DONTWAIT = 0x40
_TIMESTAMP_BYTES = 16  # struct timespec: python-can asks SO_TIMESTAMPNS
_CONTROL_BYTES = socket.CMSG_SPACE(_TIMESTAMP_BYTES)
_CONTROL_HEADER = socket.CMSG_LEN(0)
_CMSGHDR = struct.Struct("@Nii")  # struct cmsghdr: length, level, type
BATCH_FRAMES = 16
"""The most frames one ``sendmmsg(2)`` or ``recvmmsg(2)`` carries."""


class _Received:
    """One frame as ``recvmmsg(2)`` left it, answering ``recvmsg`` as a socket would, so
    that python-can's ``capture_message`` parses it."""

    __slots__ = ("answer",)

    def __init__(self, frame: bytes, control: bytes, flags: int) -> None:
        ancillary = []
        if len(control) >= _CONTROL_HEADER:
            _, level, kind = _CMSGHDR.unpack_from(control)
            ancillary.append((level, kind, control[_CONTROL_HEADER : _CONTROL_HEADER + _TIMESTAMP_BYTES]))
        self.answer = (frame, ancillary, flags, None)

    def recvmsg(self, _bufsize: int, _ancbufsize: int) -> tuple[bytes, list, int, None]:
        return self.answer


class BatchSendError(can.CanOperationError):
    """A frame of a batch could not be sent: ``sent`` frames before it were (in order), the
    rest were not. ``error_code``: the OS error (``ENOBUFS`` or ``EAGAIN``: the transmit
    queue is full; ``ENETDOWN``: the interface is down)."""

    def __init__(self, message: str, error_code: int | None, sent: int) -> None:
        super().__init__(message, error_code)
        self.sent = sent


class LeanSocketcanBus(SocketcanBus):
    """A :class:`~can.interfaces.socketcan.SocketcanBus` on one CAN interface (``channel``
    must name it) on which a cycle's frames cost one system call each way (see the module).

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
        self._batch_iov = (_IoVec * BATCH_FRAMES)()
        self._batch_headers = (_MMsgHdr * BATCH_FRAMES)()
        for header, iov in zip(self._batch_headers, self._batch_iov):
            header.msg_hdr.msg_iov = ctypes.pointer(iov)
            header.msg_hdr.msg_iovlen = 1
        self._received: deque[can.Message] = deque()
        self._empty_when_read = False  # the last recvmmsg(2) left the socket's queue empty
        self._rx_written = BATCH_FRAMES  # headers to reset before the next recvmmsg(2): at first, all
        self._rx_frames = ctypes.create_string_buffer(CANFD_MTU * BATCH_FRAMES)
        self._rx_control = ctypes.create_string_buffer(_CONTROL_BYTES * BATCH_FRAMES)
        self._rx_iov = (_IoVec * BATCH_FRAMES)()
        self._rx_headers = (_MMsgHdr * BATCH_FRAMES)()
        for i, (header, iov) in enumerate(zip(self._rx_headers, self._rx_iov)):
            iov.iov_base, iov.iov_len = ctypes.addressof(self._rx_frames) + i * CANFD_MTU, CANFD_MTU
            header.msg_hdr.msg_iov = ctypes.pointer(iov)
            header.msg_hdr.msg_iovlen = 1
            header.msg_hdr.msg_control = ctypes.addressof(self._rx_control) + i * _CONTROL_BYTES

    @property
    def receive_buffer_bytes(self) -> int:
        """The socket's receive buffer as the kernel reports it (twice what was granted)."""
        return self.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg``; with ``timeout`` 0 or None at once or not at all (one system call),
        else waiting up to ``timeout`` s for room: in the socket (python-can's send) and in
        the interface's transmit queue (ENOBUFS: tried again every :data:`QUEUE_FULL_POLL_S`).

        :raises can.CanOperationError: the frame was not sent (``error_code``: the OS error)
        """
        if timeout:
            self._send_waiting(msg, timeout)
            return
        data = build_can_frame(msg)
        try:
            sent = self.socket.send(data)
        except OSError as error:
            raise can.CanOperationError(f"Failed to transmit: {error.strerror}", error.errno) from error
        if sent != len(data):
            raise can.CanOperationError("Transmit buffer full")

    def _send_waiting(self, msg: can.Message, timeout: float) -> None:
        # python-can's send waits in select(2), which says a CAN socket is writable while the
        # interface's queue is full, so it raises ENOBUFS at once: try again until the timeout.
        deadline = time.monotonic() + timeout
        while True:
            try:
                super().send(msg, max(deadline - time.monotonic(), 0.0))
                return
            except can.CanOperationError as error:
                if error.error_code not in _QUEUE_FULL or time.monotonic() >= deadline:
                    raise
            time.sleep(QUEUE_FULL_POLL_S)

    def send_batch(self, msgs: Sequence[can.Message]) -> None:
        """Send ``msgs`` in order without waiting for room, :data:`BATCH_FRAMES` to a system call.
        One thread at a time (the batch's buffers are the bus's); :meth:`send` may run beside it.

        :raises BatchSendError: a frame could not be sent; those before it were
            (:attr:`BatchSendError.sent`), it and those after it were not
        """
        frames = [build_can_frame(msg) for msg in msgs]
        sent = 0
        while sent < len(frames):
            chunk = frames[sent : sent + BATCH_FRAMES]
            # One buffer for the chunk, kept alive until the call returns.
            buffer = ctypes.create_string_buffer(b"".join(chunk), sum(map(len, chunk)))
            address = ctypes.addressof(buffer)
            for iov, frame in zip(self._batch_iov, chunk):
                iov.iov_base, iov.iov_len = address, len(frame)
                address += len(frame)
            done = _sendmmsg(self.socket.fileno(), self._batch_headers, len(chunk), 0)
            if done < 0:
                code = ctypes.get_errno()
                raise BatchSendError(f"Failed to transmit: {os.strerror(code)}", code, sent)
            sent += done
            if done < len(chunk):
                # sendmmsg(2) reports the error of a frame after the first only by stopping
                # there; sending that frame alone says why (or sends it, if room has appeared).
                try:
                    self.send(msgs[sent])
                except can.CanOperationError as error:
                    raise BatchSendError(str(error), error.error_code, sent) from error
                sent += 1

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame that passes the filters, or None; with ``timeout`` 0 without
        waiting, else python-can's receive. What has arrived is read in one system call and
        handed out one frame a call; a call with ``timeout`` 0 after the read that emptied
        the socket's queue says None without another (nothing had arrived microseconds ago),
        the next one reads again.

        :raises can.CanOperationError: the receive failed (``error_code``: the OS error)
        """
        if timeout != 0:
            return super().recv(timeout)
        while True:
            while self._received:
                msg = self._received.popleft()
                if self._is_filtered or self._matches_filters(msg):
                    return msg
            if self._empty_when_read:
                self._empty_when_read = False
                return None
            self._read_arrived()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._received:
            try:
                ready = select.select([self.socket], [], [], timeout)[0]
            except OSError as error:
                raise can.CanOperationError(f"Failed to receive: {error.strerror}", error.errno) from error
            if not ready:
                return None, self._is_filtered
            self._read_arrived()
        return (self._received.popleft() if self._received else None), self._is_filtered

    def _read_arrived(self) -> None:
        """Queue what has arrived, up to :data:`BATCH_FRAMES` frames, in one ``recvmmsg(2)``."""
        headers = self._rx_headers
        for header in headers[: self._rx_written]:  # what the kernel rewrote for the frames it filled
            header.msg_hdr.msg_controllen = _CONTROL_BYTES
            header.msg_hdr.msg_flags = 0
        count = _recvmmsg(self.socket.fileno(), headers, BATCH_FRAMES, _MSG_DONTWAIT, None)
        self._rx_written = max(count, 1)  # a failed call may have written the first
        if count < 0:
            code = ctypes.get_errno()
            if code in _NOTHING_WAITING:
                self._empty_when_read = True
                return
            raise can.CanOperationError(f"Error receiving: {os.strerror(code)}", code)
        self._empty_when_read = count < BATCH_FRAMES
        frames, control = self._rx_frames.raw, self._rx_control.raw
        for i in range(count):
            header = headers[i]
            at, control_at = i * CANFD_MTU, i * _CONTROL_BYTES
            received = _Received(frames[at : at + header.msg_len],
                                 control[control_at : control_at + header.msg_hdr.msg_controllen],
                                 header.msg_hdr.msg_flags)  # fmt: skip
            msg = capture_message(received)  # type: ignore[arg-type]  # python-can's parsing
            msg.channel = self.channel
            self._received.append(msg)
