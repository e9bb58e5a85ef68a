"""What a campaign tells its operator while it works: sentences on one stream (stdout)
and a text progress bar on another (stderr), so that redirecting the output keeps the
sentences and drops the bar's redraws."""

from __future__ import annotations

import sys
from typing import TextIO

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
        self._tenths = -1
        self._drawn = False

    def say(self, text: str) -> None:
        self._clear()
        print(text, file=self.out, flush=True)

    def start(self, title: str, total: int, done: int = 0) -> None:
        """A phase of ``total`` steps begins, ``done`` of them already done (a resumed campaign)."""
        self.title, self._total, self._tenths = title, total, -1
        self._draw(done, "resumed" if done else "")

    def step(self, done: int, label: str) -> None:
        """``done`` steps of the phase are finished, the latest being ``label``."""
        self._draw(done, label)

    def finish(self) -> None:
        self._clear()

    def _draw(self, done: int, label: str) -> None:
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
