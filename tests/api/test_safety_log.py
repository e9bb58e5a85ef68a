"""The service's log says what happened to the platform: each state change with its faults,
and each of the loop's events, once (found from outside: after a fault on all six legs, an
E-stop, a reset and two calibration swaps the log held nothing beyond the start-up lines)."""

from __future__ import annotations

import logging
from dataclasses import replace

import pytest

from hexactl.application.safety_log import SafetyLog
from hexactl.control.core import KEPT_EVENTS
from hexactl.control.snapshot import ControlState, Event
from hexactl.control.supervisor import Fault
from tests.control.conftest import Rig


@pytest.fixture
def snapshot(nominal):
    rig = Rig(nominal)
    rig.run()
    return rig.controller.snapshot


def test_state_changes_and_new_events_are_logged_once(snapshot, caplog) -> None:
    caplog.set_level(logging.INFO, logger="hexactl.safety")
    safety = SafetyLog()
    history = (Event(1, 1, "estop", "an E-stop before the service's API started"),)
    safety.observe(replace(snapshot, state=ControlState.DISABLED, events=history))
    safety.observe(replace(snapshot, state=ControlState.ENABLED, events=history))
    fault = Fault("heartbeat_lost", "leg 3 silent for 0.05 s", 3)
    faulted = replace(snapshot, state=ControlState.FAULT, faults=(fault,),
                      events=(*history, Event(2, 5, fault.code, fault.message)))
    safety.observe(faulted)
    safety.observe(faulted)  # the same report again: nothing new
    swapped = (*faulted.events, Event(3, 9, "calibration_swapped", "calibration a → b from cal.toml", "hexactl ann@b2 (::1)"),
               Event(4, 10, "sequence_started", "sequence 'x_sweep': 9 waypoints"),
               Event(5, 11, "estop", "estop command", "dashboard (127.0.0.1)"),
               Event(6, 11, "stop", "any motion under way brakes to rest", "dashboard (127.0.0.1)"))
    safety.observe(replace(snapshot, state=ControlState.DISABLED, events=swapped))
    lines = [(record.levelname, record.getMessage()) for record in caplog.records]
    assert lines == [
        ("INFO", f"state disabled → enabled (calibration {snapshot.active.calibration_id})"),
        ("WARNING", "loop heartbeat_lost: leg 3 silent for 0.05 s"),
        ("WARNING", f"state enabled → fault (heartbeat_lost: leg 3 silent for 0.05 s) (calibration "
                    f"{snapshot.active.calibration_id})"),
        ("INFO", "loop calibration_swapped: calibration a → b from cal.toml (sent by hexactl ann@b2 (::1))"),
        ("INFO", "loop sequence_started: sequence 'x_sweep': 9 waypoints"),
        ("WARNING", "loop estop: estop command (sent by dashboard (127.0.0.1))"),
        ("INFO", "loop stop: any motion under way brakes to rest (sent by dashboard (127.0.0.1))"),
        ("INFO", f"state fault → disabled (calibration {snapshot.active.calibration_id})"),
    ]


def test_events_the_loop_no_longer_kept_are_counted_not_silently_skipped(snapshot, caplog) -> None:
    caplog.set_level(logging.INFO, logger="hexactl.safety")
    safety = SafetyLog()
    safety.observe(replace(snapshot, events=(Event(7, 1, "enabled", "the actuators hold the pose they are at"),)))
    burst = tuple(Event(seq, 2, "command_refused", f"refusal {seq}") for seq in range(8 + 3, 8 + 3 + KEPT_EVENTS))
    safety.observe(replace(snapshot, events=burst))
    lines = [record.getMessage() for record in caplog.records]
    assert lines[0] == (f"3 of the loop's events are not logged: more came between two of its reports than it keeps "
                        f"({KEPT_EVENTS})")
    assert lines[1:] == [f"loop command_refused: refusal {seq}" for seq in range(11, 11 + KEPT_EVENTS)]
