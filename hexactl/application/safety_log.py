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

from hexactl.control.snapshot import ControlState, CoreSnapshot

log = logging.getLogger("hexactl.safety")

_WARNING_STATES = (ControlState.FAULT, ControlState.ESTOP)

_ROUTINE_EVENTS = ("sequence_", "jog_", "stream_", "wave_", "leg_locked", "leg_unlocked", "calibration_swapped",
                   "command_refused", "command_link_heard", "enabled", "disabled", "stop", "reset", "move", "pause",
                   "resume", "abort")
"""Codes (or their prefixes) of the loop's events that are its daily work, logged as INFO;
the others (faults such as ``leg_lock_projection``, E-stops, a guard's clamp) as WARNING.
The dashboard's Events panel draws the same line (``events.js``, ``isWarning``)."""


class SafetyLog:
    """Logs what is new in each snapshot it observes (one observer thread)."""

    def __init__(self) -> None:
        self._state: ControlState | None = None
        self._last_event_ns = -1

    def observe(self, snapshot: CoreSnapshot) -> None:
        if self._state is None:  # the first report: the events before it are the loop's history, not news
            self._state = snapshot.state
            self._last_event_ns = max((event.t_ns for event in snapshot.events), default=-1)
            return
        for event in snapshot.events:
            if event.t_ns > self._last_event_ns:
                level = logging.INFO if event.code.startswith(_ROUTINE_EVENTS) else logging.WARNING
                log.log(level, "loop %s: %s%s", event.code, event.message,
                        f" (sent by {event.sender})" if event.sender else "")
        self._last_event_ns = max((event.t_ns for event in snapshot.events), default=self._last_event_ns)
        if snapshot.state is not self._state:
            level = logging.WARNING if snapshot.state in _WARNING_STATES else logging.INFO
            faults = "; ".join(f"{fault.code}: {fault.message}" for fault in snapshot.faults)
            log.log(level, "state %s → %s%s (calibration %s)", self._state.value, snapshot.state.value,
                    f" ({faults})" if faults and snapshot.state is ControlState.FAULT else "",
                    snapshot.active.calibration_id)
            self._state = snapshot.state
