"""When the loop carries a command out: pure functions of a :class:`CoreView`.

A view is the live :class:`~hexactl.control.core.ControlCore` or a
:class:`~hexactl.control.snapshot.CoreSnapshot`: both have these attributes. The
controller checks a command in the caller's thread against the latest snapshot for an
immediate answer; the loop checks it again against itself when it carries the command
out (the state may have moved). Each check returns a :data:`Refusal`.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import isinf, isnan
from typing import Protocol

from hexactl.control.commands import SwapGeometry
from hexactl.control.hardware import ActuatorFeedback, ActuatorState, BusState, FeedbackSnapshot, LinkHealth, fault_text
from hexactl.control.planning import ActiveGeometry, LegLock
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S, ErrorCode
from hexactl.control.sequence_player import SequencePhase, SequenceProgress
from hexactl.control.snapshot import ControlState, MotionState
from hexactl.control.stream import StreamPhase, StreamProgress
from hexactl.control.supervisor import STOP_OTHER_CONTROLLER, other_controller_heard
from hexactl.control.wave_player import WaveProgress

Refusal = tuple[ErrorCode, str] | None  # (code, message) or None when allowed

BUS_OFF_CHECK = ("the CAN interface left the bus after repeated transmit errors; check the bus wiring and its two "
                 "120 ohm terminations, that every node runs the same bit rate and that the actuators are powered, "
                 "then restart the interface (`ip link set can0 down` and `up`, or give it `restart-ms 100`); "
                 "enable once frames arrive again")
"""What the operator checks when enable finds the link bus-off."""


class CoreView(Protocol):
    """What the checks read (read-only); poses relative mm/rad, legs sensor mm."""

    @property
    def state(self) -> ControlState: ...
    @property
    def motion(self) -> MotionState: ...
    @property
    def sequence(self) -> SequenceProgress | None: ...
    @property
    def feedback(self) -> FeedbackSnapshot | None: ...
    @property
    def link(self) -> LinkHealth | None: ...
    @property
    def pose_measured(self) -> tuple[float, ...] | None: ...
    @property
    def active(self) -> ActiveGeometry: ...
    @property
    def lock(self) -> LegLock | None: ...
    @property
    def ramp_active(self) -> bool: ...
    @property
    def wave(self) -> WaveProgress | None: ...
    @property
    def stream(self) -> StreamProgress | None: ...


def _enabled(view: CoreView) -> Refusal:
    return check_enabled(view.state)


def check_enabled(state: ControlState) -> Refusal:
    """None when ``state`` lets the platform move; else why not and what to do first (a
    client that checks before long work, as ``hexactl cue`` before planning, says the same)."""
    if state is ControlState.ENABLED:
        return None
    if state in (ControlState.FAULT, ControlState.ESTOP):
        return ErrorCode.LATCHED, f"{state.value} is latched: reset first"
    return ErrorCode.NOT_ENABLED, "the controller is disabled: enable first"


def _wave_playing(view: CoreView) -> bool:
    return view.wave is not None and view.wave.playing


def _no_wave(view: CoreView) -> Refusal:
    return (ErrorCode.BUSY, "a wave is playing: abort it (or stop) first") if _wave_playing(view) else None


def _no_stream(view: CoreView) -> Refusal:
    if view.stream is None:
        return None
    if view.stream.phase is StreamPhase.FOLLOWING:
        return ErrorCode.BUSY, (f"stream {view.stream.stream} from {view.stream.source!r} is open: close it "
                                "(stream_close) or stop first")
    return ErrorCode.BUSY, (f"stream {view.stream.stream} from {view.stream.source!r} is closed and braking to rest: "
                            "wait until the platform is at rest (status: stream null)")


def _no_sequence(view: CoreView) -> Refusal:
    if view.sequence is None:
        return None
    doing = "paused" if view.sequence.phase is SequencePhase.PAUSED else "playing"
    return ErrorCode.BUSY, f"sequence {view.sequence.name!r} is {doing}: abort it first"


def _at_rest(view: CoreView) -> Refusal:
    if refusal := _no_wave(view) or _no_stream(view) or _no_sequence(view):
        return refusal
    if view.motion is not MotionState.HOLDING:
        return ErrorCode.BUSY, "the platform is moving: wait until it is at rest, or stop it"
    return None


def check_enable(view: CoreView, heartbeat_timeout_s: float) -> Refusal:
    """Of a controller not already enabled (callers answer that as done: the state asked for)."""
    if view.state is not ControlState.DISABLED:
        return ErrorCode.LATCHED, f"{view.state.value} is latched: reset first"
    if view.feedback is None:
        return ErrorCode.HEARTBEAT_MISSING, "no feedback from the actuators yet"
    if view.link is not None and view.link.bus_state is BusState.BUS_OFF:
        # The loop would latch link_failed at once: say what to check instead. (A bus DOWN
        # silences every leg, which the check below reports with the link's note.)
        detail = f" ({view.link.detail})" if view.link.detail else ""
        return ErrorCode.SEND_FAILED, f"the link reports the CAN bus off{detail}: {BUS_OFF_CHECK}"
    if heard := other_controller_heard(view.link):
        return ErrorCode.OTHER_CONTROLLER, (f"{heard}: two controllers would drive the same actuators; "
                                            f"{STOP_OTHER_CONTROLLER}, then enable once none has been heard for "
                                            f"{OTHER_CONTROLLER_WINDOW_S:g} s")
    low, high = view.active.stroke
    for leg, actuator in enumerate(view.feedback.actuators, start=1):
        if not actuator.heartbeat_age_s <= heartbeat_timeout_s:
            age = "yet" if isinf(actuator.heartbeat_age_s) else f"for {actuator.heartbeat_age_s:.3f} s"
            return ErrorCode.HEARTBEAT_MISSING, f"leg {leg}: no report {age}{_link_note(view.link)}"
        if faulted := _faulted(leg, actuator):
            cleared_soon = (" (after a reset an actuator leaves ESTOP once it has seen no E-stop for a moment: "
                            "enable again shortly)" if actuator.state is ActuatorState.ESTOP else "")
            return ErrorCode.ACTUATOR_FAULT, f"{faulted}{cleared_soon}"
        if isnan(actuator.position_mm):
            return ErrorCode.HEARTBEAT_MISSING, f"leg {leg}: no position reported yet"
        if not low <= actuator.position_mm <= high:
            return ErrorCode.OUTSIDE_STROKE, f"leg {leg} at {actuator.position_mm:.3f} mm, outside the stroke [{low:g}, {high:g}] mm"
    if view.pose_measured is None:
        return ErrorCode.POSE_UNKNOWN, "forward kinematics of the feedback failed: the platform's pose is unknown"
    return None


def actuator_faulted(feedback: FeedbackSnapshot | None) -> str | None:
    """The first actuator reporting FAULT, ESTOP or fault bits (``leg N: ESTOP, faults: …``),
    for which enable is refused; None if none does (or no feedback)."""
    for leg, actuator in enumerate(feedback.actuators if feedback is not None else (), start=1):
        if faulted := _faulted(leg, actuator):
            return faulted
    return None


def _faulted(leg: int, actuator: ActuatorFeedback) -> str | None:
    if actuator.state in (ActuatorState.FAULT, ActuatorState.ESTOP) or actuator.fault_bits:
        return f"leg {leg}: {actuator.state.name}, faults: {fault_text(actuator.fault_names, actuator.fault_bits)}"
    return None


def _link_note(link: LinkHealth | None) -> str:
    """What the link says beside a silent leg: often the cause (an interface down, a bus
    off or error-passive, an actuator speaking another protocol), which only it knows."""
    notes = [] if link is None or link.bus_state is BusState.ACTIVE else [f"bus {link.bus_state.value}"]
    if link is not None and link.detail:
        notes.append(link.detail)
    return f" (link: {'; '.join(notes)})" if notes else ""


def check_disable(view: CoreView) -> Refusal:
    if view.state is ControlState.DISABLED:
        return ErrorCode.NOT_ENABLED, "the controller is already disabled"
    return _enabled(view) or _at_rest(view)


def check_move(view: CoreView) -> Refusal:
    return _enabled(view) or _no_wave(view) or _no_stream(view) or _no_sequence(view)


def _all_six_legs(view: CoreView, what: str) -> Refusal:
    if view.lock is not None:
        return ErrorCode.LEG_LOCKED, f"leg {view.lock.leg} is locked: {what} needs all six legs (unlock first)"
    return None


def _not_ramping(view: CoreView) -> Refusal:
    return (ErrorCode.BUSY, "a calibration change is still ramping in") if view.ramp_active else None


def check_jog(view: CoreView) -> Refusal:
    return check_move(view) or _all_six_legs(view, "a jog")


def check_lock(view: CoreView) -> Refusal:
    if refusal := _enabled(view) or _at_rest(view):
        return refusal
    if view.lock is not None:
        return ErrorCode.LEG_LOCKED, f"leg {view.lock.leg} is already locked: unlock it first (one leg at a time)"
    return _not_ramping(view)


def check_unlock(view: CoreView) -> Refusal:
    if view.lock is None:  # first: disabling or a reset ended it, and enabling would not help
        return ErrorCode.NOT_LOCKED, "no leg is locked"
    return _enabled(view) or _at_rest(view)


def check_play(view: CoreView) -> Refusal:
    return _enabled(view) or _at_rest(view)


def check_pause(view: CoreView) -> Refusal:
    if _wave_playing(view):
        return ErrorCode.BUSY, "a wave cannot be paused: abort it (or stop), and it brakes to rest"
    if view.sequence is None:
        return ErrorCode.NO_SEQUENCE, "no sequence is playing"
    if view.sequence.phase in (SequencePhase.PAUSING, SequencePhase.PAUSED):
        return ErrorCode.ALREADY_PAUSED, "the sequence is already paused"
    return None


def check_resume(view: CoreView) -> Refusal:
    if view.sequence is None:
        return ErrorCode.NO_SEQUENCE, "no sequence is playing"
    if view.sequence.phase is SequencePhase.PAUSING:
        return ErrorCode.NOT_PAUSED, "the sequence is still braking to its pause: resume once it is paused"
    if view.sequence.phase is not SequencePhase.PAUSED:
        return ErrorCode.NOT_PAUSED, f"the sequence is {view.sequence.phase.value}, not paused: pause it first"
    return None


def check_abort(view: CoreView) -> Refusal:
    if view.sequence is not None or _wave_playing(view):
        return None
    return ErrorCode.NO_SEQUENCE, "no sequence or wave is playing"


def check_wave(view: CoreView) -> Refusal:
    return _enabled(view) or _at_rest(view) or _all_six_legs(view, "a wave") or _not_ramping(view)


def check_set_frames(view: CoreView) -> Refusal:
    """At rest only: a motion keeps the frames and soft limits it was planned in, so new
    soft limits set under way would neither stop it nor let the platform back inside."""
    if refusal := _at_rest(view):
        code, message = refusal
        return code, f"{message}: frames and soft limits change only at rest (a motion keeps those it was planned in)"
    return None


def check_reset(view: CoreView) -> Refusal:
    if view.state is ControlState.ENABLED:
        return ErrorCode.NOT_LATCHED, "nothing to reset: the controller is enabled (disable or estop)"
    return None


def check_stream(view: CoreView) -> Refusal:
    return _enabled(view) or _at_rest(view) or _all_six_legs(view, "a stream") or _not_ramping(view)


def check_swap(view: CoreView, new: ActiveGeometry) -> Refusal:
    # The new geometry's limits equal the hardware's (Controller.load_calibration), so
    # the set-points already respect its stroke. A stream's targets were checked on the
    # geometry it opened with.
    if refusal := _no_wave(view) or _no_stream(view):
        return refusal
    if view.lock is not None:
        if view.state in (ControlState.FAULT, ControlState.ESTOP):  # latched, unlock is refused
            return ErrorCode.LEG_LOCKED, (f"leg {view.lock.leg} is locked and {view.state.value} is latched: reset "
                                          "(which ends the lock) before changing the calibration")
        return ErrorCode.LEG_LOCKED, f"leg {view.lock.leg} is locked: unlock before changing the calibration"
    return None


def check_rollback(history: Sequence[ActiveGeometry], swap: SwapGeometry) -> Refusal:
    """A rollback's calibration must still be the last of the ``history`` (another client
    may have loaded or rolled back since it was checked). By id: it crossed a process."""
    if swap.rollback and (not history or history[-1].calibration_id != swap.active.calibration_id):
        return ErrorCode.STALE_PLAN, "the calibration history changed meanwhile: roll back again"
    return None
