"""Sending a pose stream from Python: open it through the API, push samples, close it.

::

    with HexactlClient() as client, PoseStream(client, "my tracker") as stream:
        for pose in poses:               # x, y, z mm and roll, pitch, yaw deg, in the stream's frame
            stream.send(pose)
            time.sleep(0.002)

The samples go on a ZeroMQ PUSH socket to the endpoint ``stream_open`` named, in the
binary layout of :mod:`hexactl.adapters.api.stream_wire`, numbered and stamped with this
host's monotonic clock. A sample the socket cannot take at once (the service is gone or
not reading) is dropped and counted rather than queued: a late target is worth nothing.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from types import TracebackType
from typing import Any, Self

import zmq

from hexactl.adapters.api.client import CommandError, HexactlClient, ServiceUnavailable, ZmqConnection
from hexactl.adapters.api.stream_wire import encode

SEND_QUEUE = 16
"""Samples the socket may hold before :meth:`PoseStream.send` drops one."""


class PoseStream:
    """A stream from ``source`` (a name for people) of poses in ``frame`` (``zero`` or
    ``work``), ended by the service when no sample comes for ``timeout_ms``, through
    ``client`` (its CURVE keys, if any, secure the stream too). Opened by ``with`` (or
    :meth:`open`), closed on leaving it.

    :raises hexactl.adapters.api.client.CommandError: the service refused to open it
    :raises hexactl.adapters.api.client.ServiceUnavailable: its stream socket did not connect
    """

    def __init__(self, client: HexactlClient, source: str, *, frame: str = "zero", timeout_ms: float = 100.0) -> None:
        self._client = client
        self._request = {"source": source, "frame": frame, "timeout_ms": timeout_ms}
        self._push: ZmqConnection | None = None
        self._sequence = 0
        self.opened: dict[str, Any] | None = None
        """``stream_open``'s reply: ``stream``, ``velocity_scale``, ``endpoints``."""
        self.dropped = 0
        """Samples not sent because the socket could not take them at once."""

    def open(self) -> Self:
        self.opened = self._client.call("stream_open", **self._request)
        endpoint = beside_api(self.opened["endpoints"]["zmq"], self._client.endpoint)
        self._push = ZmqConnection(zmq.PUSH, endpoint, self._client.curve, {zmq.SNDHWM: SEND_QUEUE, zmq.IMMEDIATE: 1})
        # IMMEDIATE: nothing is queued before the connection is up, so wait for it rather
        # than drop the first samples.
        if not self._push.socket.poll(round(self._client.timeout_s * 1000), zmq.POLLOUT):
            self.close()
            raise ServiceUnavailable(f"the stream socket {endpoint} did not connect within {self._client.timeout_s:g} s")
        return self

    def send(self, pose: Sequence[float], sent_s: float | None = None) -> bool:
        """Send ``pose`` (x, y, z mm, roll, pitch, yaw deg), stamped ``sent_s`` (default:
        now, this host's monotonic clock, s); False if dropped.

        :raises struct.error: not six numbers
        """
        if self._push is None:
            raise RuntimeError("the stream is not open: use it in a with statement, or call open()")
        self._sequence += 1
        message = encode(self._sequence, time.monotonic() if sent_s is None else sent_s, list(pose))
        try:
            self._push.socket.send(message, zmq.NOBLOCK)
        except zmq.Again:
            self.dropped += 1
            return False
        return True

    def send_paced(self, poses: Sequence[Sequence[float]], period_s: float) -> int:
        """Send ``poses`` one every ``period_s`` in real time (absolute deadlines: a late
        one does not delay the rest); the samples dropped."""
        start = time.monotonic()
        dropped = self.dropped
        for n, pose in enumerate(poses):
            time.sleep(max(0.0, start + n * period_s - time.monotonic()))
            self.send(pose)
        return self.dropped - dropped

    def close(self) -> None:
        """Close the stream (the platform brakes to rest) and the socket. A stream the
        service already ended (its timeout, a stop, a fault) is closed too."""
        if self._push is not None:
            self._push.close()
            self._push = None
            try:
                self._client.call("stream_close")
            except CommandError as error:
                if error.code != "no_stream":
                    raise

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None) -> None:
        self.close()


def beside_api(stream_endpoint: str, api_endpoint: str) -> str:
    """``stream_endpoint`` as a client connects to it: a wildcard host (the service bound
    every interface) is the host the client reaches the API at."""
    if stream_endpoint.startswith("tcp://0.0.0.0:") and api_endpoint.startswith("tcp://"):
        return api_endpoint.rpartition(":")[0] + ":" + stream_endpoint.rpartition(":")[2]
    return stream_endpoint
