"""What a campaign tells its operator while it works: sentences on one stream (stdout)
and a text progress bar on another (stderr), so that redirecting the output keeps the
sentences and drops the bar's redraws."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, TextIO

Forward = Callable[[dict[str, Any]], None]
"""Where a copy of the progress goes (the service's ``progress`` command: displays show it)."""

BAR_WIDTH = 30
"""Characters of the bar itself."""


class Progress:
    """Sentences with :meth:`say`, a bar per phase with :meth:`start`, :meth:`step` and
    :meth:`finish`. On a terminal the bar redraws in place; elsewhere (a log file, a
    pipe) it prints a line at every tenth of the phase.

    :meth:`step` is called after each measurement has been saved: a subclass that raises
    there interrupts a campaign exactly between two measurements (tests do).
    """

    def __init__(self, out: TextIO | None = None, bar: TextIO | None = None) -> None:
        self.out = out or sys.stdout
        self.bar = bar or sys.stderr
        self.title = ""
        """The phase being shown."""
        self._total = 0
        self._done = 0
        self._label = ""
        self._tenths = -1
        self._drawn = False
        self._forward: Forward | None = None

    def forward_to(self, forward: Forward | None) -> None:
        """Also hand every phase, step and sentence to ``forward`` (None: no longer), as the
        fields of the API's ``progress`` command."""
        self._forward = forward

    def report(self, report: dict[str, Any]) -> None:
        """The finished campaign's results (the fields of the API's ``CampaignReport``), for displays."""
        self._send(report=report)

    def say(self, text: str) -> None:
        """Print ``text``; forward it a line at a time (the API takes one line of text: a
        display prints it), blank lines left out."""
        self._clear()
        print(text, file=self.out, flush=True)
        for line in text.splitlines():
            if line.strip():
                self._send(said=line)

    def start(self, title: str, total: int, done: int = 0) -> None:
        """A phase of ``total`` steps begins, ``done`` of them already done (a resumed campaign)."""
        self.title, self._total, self._tenths = title, total, -1
        self._draw(done, "resumed" if done else "")
        self._send()

    def step(self, done: int, label: str) -> None:
        """``done`` steps of the phase are finished, the latest being ``label``."""
        self._draw(done, label)
        self._send()

    def _send(self, **extra: Any) -> None:
        if self._forward is not None:
            self._forward({"title": self.title, "done": self._done, "total": self._total, "label": self._label, **extra})

    def finish(self) -> None:
        self._clear()

    def _draw(self, done: int, label: str) -> None:
        self._done, self._label = done, label
        filled = BAR_WIDTH * done // self._total if self._total else BAR_WIDTH
        text = f"{self.title} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {done}/{self._total} {label}"
        if self.bar.isatty():
            self.bar.write(f"\r{text}\x1b[K")
            self._drawn = True
        else:
            tenths = 10 * done // self._total if self._total else 10
            if tenths == self._tenths:
                return
            self._tenths = tenths
            self.bar.write(text + "\n")
        self.bar.flush()

    def _clear(self) -> None:
        if self._drawn:
            self.bar.write("\r\x1b[K")
            self.bar.flush()
            self._drawn = False
