"""What clients' campaigns say about themselves (``progress``), kept for telemetry: a
display such as the dashboard shows a campaign that runs in another process, perhaps on
another machine, through the service it drives."""

from __future__ import annotations

import time
from collections import deque
from typing import Any

from hexactl.adapters.api.messages import ProgressRequest

SENTENCES_KEPT = 12
"""The campaign's latest sentences that telemetry carries: at most this many …"""

SAID_CHARACTERS_KEPT = 4000
"""… and at most this many characters of them, the newest sentence always whole (it is at
most 2000): every telemetry record carries them, at up to 200 records a second."""


class CampaignBoard:
    """The latest progress, replaced whole (the API thread writes, telemetry's reads)."""

    def __init__(self, clock=time.monotonic) -> None:  # noqa: ANN001 - a monotonic clock, s
        self._clock = clock
        self._said: deque[str] = deque(maxlen=SENTENCES_KEPT)
        self._latest: tuple[dict[str, Any], float] | None = None

    def update(self, request: ProgressRequest) -> None:
        if request.said is not None:
            self._said.append(request.said)
            while sum(map(len, self._said)) > SAID_CHARACTERS_KEPT:
                self._said.popleft()
        report = request.report.model_dump(mode="json") if request.report is not None else None
        if report is None and self._latest is not None:
            report = self._latest[0]["report"]  # a report stays until the next campaign's first phase
        if request.done == 0 and request.report is None and request.said is None:
            report = None
        self._latest = ({"title": request.title, "done": request.done, "total": request.total,
                         "label": request.label, "said": list(self._said), "report": report}, self._clock())

    def view(self) -> dict[str, Any] | None:
        """The telemetry's ``campaign`` field (None before any progress)."""
        latest = self._latest
        if latest is None:
            return None
        fields, when = latest
        return {**fields, "age_s": self._clock() - when}
