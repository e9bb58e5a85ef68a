"""The dashboard's HTTP connections: uvicorn's HTTP/1.1 protocol with a deadline for each
request's head and a bound on connections still waiting for one.

uvicorn waits for an unfinished request for as long as its connection stays open, so
connections opened and left silent (a stuck script, a tunnel whose far end vanished, a
local process doing it on purpose) piled up until the dashboard ran out of file
descriptors, and a page that reconnected could no longer send its E-stop. A connection
that has sent no complete request head within :attr:`GuardedH11Protocol.head_timeout_s`
(since it opened, or since its last response) is closed; so is the oldest of them when
more than :attr:`GuardedH11Protocol.max_awaiting_head` wait at once. A page's open
WebSocket, or a request being answered, waits for no head and is never closed by either.
"""

from __future__ import annotations

import asyncio

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol


class GuardedH11Protocol(H11Protocol):
    """:class:`~uvicorn.protocols.http.h11_impl.H11Protocol` with the deadline and bound
    above (``uvicorn.Config(http=GuardedH11Protocol)``)."""

    head_timeout_s = 10.0
    """A browser sends its request at once; a preconnected socket it left idle and
    closed here is opened again when needed."""

    max_awaiting_head = 256

    _deadline: asyncio.TimerHandle | None = None
    _waiting_since = 0.0

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._await_head()
        waiting = [connection for connection in self.connections
                   if isinstance(connection, GuardedH11Protocol) and connection._awaiting_head()]
        if len(waiting) > self.max_awaiting_head:
            min(waiting, key=lambda connection: connection._waiting_since).transport.close()

    def handle_events(self) -> None:
        super().handle_events()
        if not self._awaiting_head():
            self._stop_waiting()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._await_head()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_waiting()
        super().connection_lost(exc)

    def _await_head(self) -> None:
        self._stop_waiting()
        if self._awaiting_head():
            self._waiting_since = self.loop.time()
            self._deadline = self.loop.call_later(self.head_timeout_s, self._head_overdue)

    def _awaiting_head(self) -> bool:
        # IDLE until a request's head is complete: h11 moves on only then (and stays
        # past it for a WebSocket upgrade, whose transport the WebSocket protocol owns).
        return self.conn.their_state is h11.IDLE and not self.transport.is_closing()

    def _stop_waiting(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _head_overdue(self) -> None:
        self._deadline = None
        if self._awaiting_head():
            self.transport.close()
