"""A ZeroMQ socket served by a thread of its own: the lifecycle the command server and the
telemetry publisher share.

The socket is made and bound when the object is made (so a bad or busy endpoint is an
error there, with nothing left open), served by one daemon thread from :meth:`start`,
and closed by :meth:`close` once the thread has stopped. Between the two the socket
belongs to that thread: ZeroMQ sockets are not thread-safe.
"""

from __future__ import annotations

import errno
import os
import socket
import stat
import threading
from abc import ABC, abstractmethod
from collections.abc import Mapping

import zmq

from hexactl.adapters.api.security import CurveServer


class SocketThread(ABC):
    """A socket of ``kind`` bound to ``endpoint`` (``tcp://HOST:*`` picks a free port),
    with ``options`` (``zmq`` option → value) and CURVE when ``curve`` is given, and a
    thread named ``name`` running :meth:`_run`.

    Subclasses implement :meth:`_run`: it owns ``self._socket`` and returns soon after
    ``self._stopping`` is set, which bounds how long :meth:`close` waits.

    :raises zmq.ZMQError: the endpoint is malformed or in use, or an ``ipc://`` path
        holds what is not a stale socket (the socket is closed)
    """

    def __init__(
        self,
        context: zmq.Context,
        kind: int,
        endpoint: str,
        *,
        name: str,
        options: Mapping[int, int] | None = None,
        curve: CurveServer | None = None,
    ) -> None:
        self._stopping = threading.Event()
        self._socket = context.socket(kind)
        try:
            self._socket.linger = 0  # closing drops what is unsent: a peer that is gone must not hold up shutdown
            for option, value in (options or {}).items():
                self._socket.setsockopt(option, value)
            if curve is not None:
                curve.secure(self._socket)
            _refuse_to_replace(endpoint)
            self._socket.bind(endpoint)
        except BaseException:
            self._socket.close()
            raise
        self.endpoint: str = self._socket.getsockopt_string(zmq.LAST_ENDPOINT)
        """Where it is bound, with the port chosen for ``*``."""
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        """Start serving in the thread."""
        self._thread.start()

    def close(self) -> None:
        """Stop the thread (as soon as :meth:`_run` sees ``_stopping``), then close the
        socket. Also for an object never started, and more than once."""
        self._stopping.set()
        if self._thread.is_alive():
            self._thread.join()
        self._release()
        self._socket.close()

    def _release(self) -> None:
        """Release what a subclass's thread used besides the socket: called once the thread
        has stopped, before the socket closes (nothing here)."""

    @abstractmethod
    def _run(self) -> None:
        """The thread's work, until ``self._stopping`` is set."""


def check_bindable(endpoint: str) -> None:
    """Whether a :class:`SocketThread` could bind ``endpoint`` now: bound and closed at once,
    for a process that must know before it starts anything else (``hexactl serve`` before
    it opens the actuators).

    :raises zmq.ZMQError: as :class:`SocketThread` would; in use (EADDRINUSE), saying what to do
    """
    context = zmq.Context()
    try:
        with context.socket(zmq.PUB) as probe:
            probe.linger = 0
            _refuse_to_replace(endpoint)
            try:
                probe.bind(endpoint)
            except zmq.ZMQError as error:  # ZeroMQ's words name the port, not what to do
                if error.errno != zmq.EADDRINUSE:
                    raise
                raise zmq.ZMQError(errno.EADDRINUSE, f"{endpoint}: another process serves there (another hexactl "
                                                     "serve?): stop it first, or name another port (tcp://HOST:* "
                                                     "takes a free one)") from None
    finally:
        context.term()


def _refuse_to_replace(endpoint: str) -> None:
    """ZeroMQ binds ``ipc://PATH`` by first removing whatever is at PATH: another process's
    listening socket (a second service would take over the first one's clients, and their
    E-stop with them) or any file. Only a socket nothing listens on any more (left by a
    killed service) may go.

    :raises zmq.ZMQError: EADDRINUSE, naming the endpoint and what is there
    """
    path = endpoint.removeprefix("ipc://")
    if path == endpoint or path.startswith("@"):  # not ipc, or Linux's abstract names: no file to remove
        return
    try:
        mode = os.lstat(path).st_mode
    except OSError:  # nothing there (or nothing this process may see): ZeroMQ's bind says what is wrong
        return
    if not stat.S_ISSOCK(mode):
        raise zmq.ZMQError(errno.EADDRINUSE, f"{endpoint}: {path} exists and is not a socket; binding would replace "
                                             "it: name another path")
    with socket.socket(socket.AF_UNIX) as probe:
        probe.setblocking(False)
        try:
            probe.connect(path)
        except (ConnectionRefusedError, FileNotFoundError):
            return  # stale
        except BlockingIOError:
            pass  # a listener whose queue is full: in use all the same
        except OSError:
            return  # not ours to judge: ZeroMQ's bind says what is wrong
    raise zmq.ZMQError(errno.EADDRINUSE, f"{endpoint}: another process serves there (another hexactl serve?): "
                                         "stop it first, or name another path")
