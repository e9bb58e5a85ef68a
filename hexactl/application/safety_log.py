"""What an operator reads in the service's log after the fact: every change of the
controller's state (enabled, disabled, fault, E-stop) with its faults, and every event the
loop recorded (faults, E-stops and guard clamps as warnings; the commands it carried out,
calibration swaps, sequences, jogs and streams as information) with who sent the command
behind it, each once, from the loop's reports.

The loop keeps its events in its snapshot and never logs (a log write could stall a
cycle); the API process reads every report anyway, so it writes them down.
"""

from __future__ import annotations

import logging

from hexactl.control.core import KEPT_EVENTS
from hexactl.control.snapshot import ControlState, CoreSnapshot

log = logging.getLogger("hexactl.safety")

_WARNING_STATES = (ControlState.FAULT, ControlState.ESTOP)

_ROUTINE_EVENTS = ("sequence_", "jog_", "stream_", "wave_", "leg_locked", "leg_unlocked", "calibration_swapped",
                   "command_refused", "command_link_heard", "enabled", "disabled", "stop", "reset", "move", "pause",
                   "resume", "abort", "frames_set")
"""Codes (or their prefixes) of the loop's events that are its daily work, logged as INFO;
the others (faults such as ``leg_lock_projection``, E-stops, a guard's clamp) as WARNING.
The dashboard's Events panel draws the same line (``events.js``, ``isWarning``)."""


class SafetyLog:
    """Logs what is new in each snapshot it observes (one observer thread)."""

    def __init__(self) -> None:
        self._state: ControlState | None = None
        self._last_seq = 0

    def observe(self, snapshot: CoreSnapshot) -> None:
        last_seq = snapshot.events[-1].seq if snapshot.events else 0
        if self._state is None:  # the first report: the events before it are the loop's history, not news
            self._state = snapshot.state
            self._last_seq = last_seq
            return
        new = [event for event in snapshot.events if event.seq > self._last_seq]
        if new and new[0].seq > self._last_seq + 1:
            log.warning("%d of the loop's events are not logged: more came between two of its reports than it "
                        "keeps (%d)", new[0].seq - self._last_seq - 1, KEPT_EVENTS)
        for event in new:
            level = logging.INFO if event.code.startswith(_ROUTINE_EVENTS) else logging.WARNING
            log.log(level, "loop %s: %s%s", event.code, event.message,
                    f" (sent by {event.sender})" if event.sender else "")
        self._last_seq = max(self._last_seq, last_seq)
        if snapshot.state is not self._state:
            level = logging.WARNING if snapshot.state in _WARNING_STATES else logging.INFO
            faults = "; ".join(f"{fault.code}: {fault.message}" for fault in snapshot.faults)
            log.log(level, "state %s → %s%s (calibration %s)", self._state.value, snapshot.state.value,
                    f" ({faults})" if faults and snapshot.state is ControlState.FAULT else "",
                    snapshot.active.calibration_id)
            self._state = snapshot.state
