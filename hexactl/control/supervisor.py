"""Supervision of the actuators and the link, and the E-stop's timing.

:class:`Supervisor` decides; the core acts (latches FAULT or ESTOP, sends). While
ENABLED, :meth:`Supervisor.faults` lists what is wrong this cycle: an actuator silent
longer than ``heartbeat_timeout_s``, reporting a fault, in another state than the one
it was told to reach (after ``state_timeout_s`` to get there), not applying the
set-points (more than ``setpoint_lag_s`` behind), or farther than ``following_error_mm``
from the set-point it applied for ``following_error_s`` (jammed, overloaded, slipping:
compared with the set-point of the counter it reports, so a late frame adds nothing), a
locked leg farther than ``locked_slip_mm`` (or one cycle's step of a leg, if less) from
its locked reading as long (its brake slips);
the link failed; too many set-point sends failed in a row; another controller heard on
the bus (:func:`other_controller_heard`: the actuators would follow whichever of the two
commanded last, so the core E-stops them: :data:`ESTOP_FAULTS`; checked in FAULT too,
which holds its set-points). In any state, an actuator reporting E-stop is the hardware
chain's E-stop (:meth:`Supervisor.estop_reported`), except in the grace time a reset
gives the actuators to leave it.

E-stop timing: while ESTOP is latched the E-stop is re-sent every ``estop_repeat_s``
after the last one sent, and every cycle while none could be sent;
a reset's CLEAR_FAULT waits until ``estop_clear_holdoff_s`` after the loop's last
E-stop, because the actuators refuse it while an E-stop is recent.

Times are monotonic ns; legs 1–6. Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import ceil, isinf

from hexactl.control.config import SupervisionConfig
from hexactl.control.hardware import (
    ACTUATOR_COUNT,
    LINK_FAILED_STATES,
    ActuatorFeedback,
    ActuatorState,
    FeedbackSnapshot,
    LinkHealth,
    fault_text,
)
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S

STOP_OTHER_CONTROLLER = ("stop it (another hexactl serve, a vendor tool: `candump` on the CAN interface shows its "
                         "frames)")
"""What the operator does about another controller, in the enable refusal and the fault."""

ESTOP_FAULTS = frozenset({"other_controller"})
"""Faults whose FAULT hold cannot hold the platform: the actuators also follow another
controller's set-points, jerking between the two. The core sends the E-stop, which stops
them whoever commands (and the other controller, if it is hexactl, latches it too)."""


@dataclass(frozen=True, slots=True)
class Fault:
    """Why the loop latched FAULT or ESTOP; ``leg`` 1–6 when one actuator is the cause."""

    code: str
    message: str
    leg: int | None = None


RELEASE_FAULTS = frozenset({"following_error"})
"""Faults whose leg the FAULT hold releases, with DISABLE (a controlled stop, power off,
brake on), while the others hold: held at its set-point, a jammed leg's motor pushed
against what jams it, in stall, for as long as FAULT lasted (found from outside: 17.5 mm
short of its set-point three seconds on; the drive's own limit, larger, never came)."""


def released_legs(faults: tuple[Fault, ...]) -> list[int]:
    """The legs the FAULT hold releases for ``faults`` (:data:`RELEASE_FAULTS`)."""
    return [fault.leg for fault in faults if fault.code in RELEASE_FAULTS and fault.leg is not None]


def other_controller_heard(link: LinkHealth | None) -> str | None:
    """``another controller's SYNC was heard 0.002 s ago`` when the link heard one within
    :data:`~hexactl.control.results.OTHER_CONTROLLER_WINDOW_S`, else None."""
    if link is None or not link.other_controller_age_s <= OTHER_CONTROLLER_WINDOW_S:
        return None
    return f"another controller's {link.other_controller_frame} was heard {link.other_controller_age_s:.3f} s ago"


def other_controller_fault(link: LinkHealth | None) -> Fault | None:
    """The fault of another controller heard on the bus (:func:`other_controller_heard`),
    checked while ENABLED and while FAULT holds (both send set-points), else None."""
    if heard := other_controller_heard(link):
        return Fault("other_controller", f"{heard}: it drives these actuators too, which follow whichever "
                     f"commanded last; {STOP_OTHER_CONTROLLER}, then reset and enable")
    return None


class Supervisor:
    """The supervision rules and timers of one loop running every ``period_s``, whose
    legs move at most ``max_step_mm`` a cycle."""

    def __init__(self, supervision: SupervisionConfig, period_s: float, max_step_mm: float) -> None:
        self.heartbeat_timeout_s = supervision.heartbeat_timeout_s
        self._state_timeout_ns = round(supervision.state_timeout_s * 1e9)
        self._lag_limit = ceil(supervision.setpoint_lag_s / period_s)  # cycles
        self._following_error_mm = supervision.following_error_mm
        # never more than a step: the actuator checks the first set-point after UNLOCK from where it measures
        self._locked_slip_mm = min(supervision.locked_slip_mm, max_step_mm)
        self._following_error_ns = round(supervision.following_error_s * 1e9)
        # The set-points of the last counters sent, at counter % len: all a healthy actuator
        # may report applied (an older counter is a lag fault of its own).
        self._sent: list[tuple[int, tuple[float, ...]] | None] = [None] * (self._lag_limit + 2)
        self._following_since_ns: list[int | None] = [None] * ACTUATOR_COUNT
        self._max_send_failures = supervision.max_send_failures
        self._estop_repeat_ns = round(supervision.estop_repeat_s * 1e9)
        self._estop_clear_holdoff_ns = round(supervision.estop_clear_holdoff_s * 1e9)
        # Per leg: the state it should report, and until when it may still be getting there.
        self._expected = [ActuatorState.ENABLED] * ACTUATOR_COUNT
        self._settling_until_ns = [0] * ACTUATOR_COUNT
        self._send_failures = 0  # in a row
        self._first_sent: int | None = None  # counter of the first set-points sent since enabling
        self._estop_grace_until_ns = 0  # after a reset the actuators need time to leave ESTOP
        self._next_estop_ns = 0
        self._last_estop_ns: int | None = None  # when the loop last sent an E-stop
        self._clear_fault_due_ns: int | None = None  # a reset's CLEAR_FAULT waits for the E-stop hold-off
        self._clear_fault_repeat = False  # the next CLEAR_FAULT due is a repeat (sent only to an actuator in E-stop)

    def expect(self, leg: int | None, state: ActuatorState, now_ns: int) -> None:
        """Leg 1–6 (or all) must report ``state`` within ``state_timeout_s`` of ``now_ns``."""
        for i in range(ACTUATOR_COUNT) if leg is None else (leg - 1,):
            self._expected[i] = state
            self._settling_until_ns[i] = now_ns + self._state_timeout_ns
            self._following_since_ns[i] = None  # an error timed against another state's limit

    def faults(self, feedback: FeedbackSnapshot, link: LinkHealth | None, last_sent: int, now_ns: int) -> list[Fault]:
        """What is wrong while ENABLED (empty: nothing); ``last_sent`` the counter of the
        last set-points sent."""
        faults = []
        # A leg lags when the counter it applied is below this; counted at most from the first
        # set-points sent since enabling (None: not that long ago): the leg had none of this
        # session to apply before them, and a counter from before (none yet, or a rebooted
        # actuator's stale echo) says only that it applied none since. Once a call, not a leg.
        stale_below: int | None = last_sent - self._lag_limit
        if self._first_sent is not None and self._first_sent >= stale_below:
            stale_below = None
        for leg, actuator in enumerate(feedback.actuators, start=1):
            expected = self._expected[leg - 1]
            if not actuator.heartbeat_age_s <= self.heartbeat_timeout_s:
                faults.append(Fault("heartbeat_lost", _silence(leg, actuator.heartbeat_age_s, link), leg))
            elif actuator.state is ActuatorState.FAULT or actuator.fault_bits:
                faults.append(Fault("actuator_fault", f"leg {leg} reports {actuator.state.name}, faults: "
                                    f"{fault_text(actuator.fault_names, actuator.fault_bits)}", leg))
            elif actuator.state is not expected:
                if now_ns >= self._settling_until_ns[leg - 1]:
                    # a fact, not a verdict: the restart may be older than this state, and still the clue
                    restarted = (f"; it has restarted {actuator.restarts} time(s) since the link opened (a power or "
                                 "watchdog reset): check its supply and wiring" if actuator.restarts else "")
                    faults.append(Fault("actuator_state", f"leg {leg} is {actuator.state.name}, expected "
                                        f"{expected.name}{restarted}", leg))
            elif self._settling_until_ns[leg - 1]:
                self._settling_until_ns[leg - 1] = 0  # got there: from now on any deviation counts
            elif expected is ActuatorState.ENABLED and stale_below is not None and actuator.setpoint_counter < stale_below:
                faults.append(Fault("setpoints_not_applied", f"leg {leg} applied set-point {actuator.setpoint_counter}, "
                                    f"last sent {last_sent}", leg))
            elif (fault := self._following(leg, actuator, expected, now_ns)) is not None:
                faults.append(fault)
        if link is not None and link.bus_state in LINK_FAILED_STATES:
            faults.append(Fault("link_failed", f"bus {link.bus_state.value}" + (f": {link.detail}" if link.detail else "")))
        if self._send_failures >= self._max_send_failures:
            faults.append(Fault("send_failed", f"{self._send_failures} set-point sends failed in a row"))
        if fault := other_controller_fault(link):
            faults.append(fault)
        return faults

    def _following(self, leg: int, actuator: ActuatorFeedback, expected: ActuatorState, now_ns: int) -> Fault | None:
        """The fault of ``leg`` (1–6), ``expected`` ENABLED or LOCKED, farther from the
        set-point it reports applied than it may be, for too long: an enabled leg's following
        error; a locked leg's slip from its locked reading (the set-point it is sent)."""
        counter = actuator.setpoint_counter
        kept = self._sent[counter % len(self._sent)]
        if kept is None or kept[0] != counter:
            return None  # nothing of ours applied yet
        error_mm = actuator.position_mm - kept[1][leg - 1]
        locked = expected is ActuatorState.LOCKED
        limit_mm = self._locked_slip_mm if locked else self._following_error_mm
        if not abs(error_mm) > limit_mm:  # NaN too: a missing position is not an error here
            self._following_since_ns[leg - 1] = None
            return None
        since = self._following_since_ns[leg - 1]
        if since is None:
            self._following_since_ns[leg - 1] = since = now_ns
        if now_ns - since < self._following_error_ns:
            return None
        lasted = f"for {(now_ns - since) / 1e9:.3f} s (limit {limit_mm:g} mm)"
        if locked:
            return Fault("locked_leg_slipped", f"leg {leg} is {error_mm:+.3f} mm from where it was locked {lasted}: "
                         "its brake slips or the leg is overloaded; check the leg before reset and enable", leg)
        return Fault("following_error", f"leg {leg} is {error_mm:+.3f} mm from its set-point {lasted}: jammed, "
                     "overloaded or slipping; check the leg before reset and enable", leg)

    def sent(self, counter: int, setpoints: tuple[float, ...], ok: bool) -> None:
        """The set-points sent with ``counter``: kept for the following error; count a send
        that failed (``ok`` False) or end the run of failures."""
        self._sent[counter % len(self._sent)] = (counter, setpoints)
        if self._first_sent is None:
            self._first_sent = counter
        self._send_failures = 0 if ok else self._send_failures + 1

    def enabled(self, now_ns: int) -> None:
        """The actuators were told to enable at ``now_ns``: expect ENABLED, forget old send
        failures, following errors (:meth:`expect`) and the counters sent before
        (:meth:`faults`' lag)."""
        self.expect(None, ActuatorState.ENABLED, now_ns)
        self._send_failures = 0
        self._first_sent = None

    def estop_reported(self, feedback: FeedbackSnapshot, now_ns: int) -> bool:
        """An actuator reports E-stop, outside a reset's grace time."""
        if now_ns < self._estop_grace_until_ns:
            return False
        for actuator in feedback.actuators:  # every cycle, in any state: a loop, not any() of a generator
            if actuator.state is ActuatorState.ESTOP:
                return True
        return False

    def estop_sent(self, now_ns: int) -> None:
        """The loop sent an E-stop at ``now_ns`` (latching ESTOP or repeating it): the next
        is due ``estop_repeat_s`` later."""
        self._last_estop_ns = now_ns
        self._next_estop_ns = now_ns + self._estop_repeat_ns

    def estop_failed(self) -> None:
        """The loop's E-stop could not be sent: it is due again at once, every cycle until
        one goes out (the repeat interval runs only from an E-stop sent)."""
        self._next_estop_ns = 0

    def estop_due(self, now_ns: int) -> bool:
        """While ESTOP is latched: time to repeat the E-stop."""
        return now_ns >= self._next_estop_ns

    def latched_estop(self) -> None:
        """ESTOP latched again: a reset's CLEAR_FAULT still waiting is not sent."""
        self._clear_fault_due_ns = None

    def reset(self, now_ns: int) -> None:
        """A reset at ``now_ns``: schedule CLEAR_FAULT once the hold-off since the loop's
        last E-stop has passed (at once after a FAULT without E-stops), and ignore the
        actuators' E-stop for the state timeout after it, while they leave ESTOP."""
        due = now_ns
        if self._last_estop_ns is not None:
            due = max(due, self._last_estop_ns + self._estop_clear_holdoff_ns)
        self._clear_fault_due_ns = due
        self._clear_fault_repeat = False
        self._estop_grace_until_ns = due + self._state_timeout_ns

    def clear_fault_due(self, feedback: FeedbackSnapshot | None, now_ns: int) -> bool:
        """True when a reset's CLEAR_FAULT is to be sent: once its hold-off has passed, then
        every ``estop_repeat_s`` of the grace time while an actuator still reports E-stop.
        An actuator that received the loop's last E-stops late (a starved bus or host)
        refuses the first within its own hold-off; the operator's reset should not fail for
        that. Harmless otherwise: an actuator leaves E-stop only if its cause is gone."""
        due = self._clear_fault_due_ns
        if due is None or now_ns < due:
            return False
        repeat_at = now_ns + self._estop_repeat_ns
        # The last repeat leaves the actuators a repeat interval to report leaving E-stop.
        self._clear_fault_due_ns = repeat_at if repeat_at + self._estop_repeat_ns <= self._estop_grace_until_ns else None
        if not self._clear_fault_repeat:
            self._clear_fault_repeat = True
            return True
        if feedback is not None:
            for actuator in feedback.actuators:
                if actuator.state is ActuatorState.ESTOP:
                    return True
        self._clear_fault_due_ns = None  # every actuator left E-stop: done
        return False


def _silence(leg: int, age_s: float, link: LinkHealth | None) -> str:
    """What a leg's lost heartbeat reads as: its age, or, never heard in this controller's
    protocol (an actuator that restarted into another firmware), the link's word on that
    leg (its note's parts that name it)."""
    if not isinf(age_s):
        return f"leg {leg}: no report for {age_s:.3f} s"
    said = [part for part in link.detail.split("; ") if part.startswith((f"leg {leg} ", f"leg {leg}'s"))] if link else []
    return f"leg {leg}: not heard in this controller's protocol" + "".join(f": {part}" for part in said[:1])
