"""Six ideal actuators in memory: an :class:`~hexactl.control.hardware.ActuatorInterface`
for tests, benchmarks and simulation.

Each actuator follows its set-point with a first-order lag (time constant
``lag_s``) while ENABLED, holds its length while DISABLED, LOCKED (brake), FAULT or
ESTOP, and reports a heartbeat on every read. Time comes from ``clock_ns`` (default
``time.monotonic_ns``) so a test can drive it with simulated time. There is no
watchdog. Faults are injected with :meth:`silence`, :meth:`inject_fault`,
:meth:`press_estop`, :attr:`fail_sends` and :attr:`bus_state`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from math import exp, isfinite

from firmware_proto.codec import Fault
from hexactl.control.hardware import (
    ACTUATOR_COUNT,
    ActuatorCommand,
    ActuatorFeedback,
    ActuatorState,
    BusState,
    EstopCause,
    FaultNames,
    FeedbackSnapshot,
    LinkHealth,
)

_FAULT_NAMES = FaultNames(Fault)  # the real actuators' bits (PROTOCOL.md section 9), so injected faults read the same
_HOLDING = (ActuatorState.DISABLED, ActuatorState.LOCKED, ActuatorState.FAULT, ActuatorState.ESTOP)


class IdealActuators:
    """Six lagged position followers. ``record=True`` keeps every set-point call in
    :attr:`sent` as ``(counter, setpoints)`` (tests; leave it off for long runs)."""

    def __init__(
        self,
        positions_mm: Sequence[float],
        *,
        lag_s: float = 0.005,
        estop_clear_holdoff_s: float = 0.25,
        clock_ns: Callable[[], int] = time.monotonic_ns,
        record: bool = False,
    ) -> None:
        if len(positions_mm) != ACTUATOR_COUNT:
            raise ValueError(f"need {ACTUATOR_COUNT} positions, got {len(positions_mm)}")
        self.lag_s = lag_s
        self.estop_clear_holdoff_ns = round(estop_clear_holdoff_s * 1e9)
        self.clock_ns = clock_ns
        self.positions = [float(p) for p in positions_mm]
        self.velocities = [0.0] * ACTUATOR_COUNT
        self.targets = list(self.positions)
        self.states = [ActuatorState.DISABLED] * ACTUATOR_COUNT
        self.fault_bits = [0] * ACTUATOR_COUNT
        self.applied_counter = [-1] * ACTUATOR_COUNT
        self.silenced = [False] * ACTUATOR_COUNT
        self.fail_sends = False
        self.bus_state = BusState.ACTIVE
        self.send_failures = 0
        self.commands: list[tuple[int | None, ActuatorCommand]] = []
        self.estops = 0
        self.last_estop_cause: EstopCause | None = None  # why the last E-stop was sent
        self._last_estop_ns: int | None = None
        self.sent: list[tuple[int, tuple[float, ...]]] | None = [] if record else None
        now = clock_ns()
        self._last_ns = now
        self._heard_ns = [now] * ACTUATOR_COUNT

    # -- ActuatorInterface -------------------------------------------------------------

    def send_setpoints(self, counter: int, setpoints_mm: Sequence[float]) -> bool:
        if not self._sendable():
            return False
        self._advance()
        values = tuple(float(v) for v in setpoints_mm)
        if self.sent is not None:
            self.sent.append((counter, values))
        for i, value in enumerate(values):
            if self.states[i] is ActuatorState.ENABLED and isfinite(value):
                self.targets[i] = value
                self.applied_counter[i] = counter
        return True

    def send_command(self, leg: int | None, command: ActuatorCommand) -> bool:
        if not self._sendable():
            return False
        self._advance()
        self.commands.append((leg, command))
        for i in range(ACTUATOR_COUNT) if leg is None else (leg - 1,):
            self._apply(i, command)
        return True

    def send_estop(self, cause: EstopCause = EstopCause.OPERATOR) -> bool:
        if not self._sendable():
            return False
        self.estops += 1
        self.last_estop_cause = cause
        self._last_estop_ns = self.clock_ns()
        self.press_estop()
        return True

    def read_feedback(self) -> FeedbackSnapshot:
        now = self._advance()
        return FeedbackSnapshot(
            tuple(
                ActuatorFeedback(
                    position_mm=self.positions[i],
                    velocity_mm_s=self.velocities[i],
                    state=self.states[i],
                    fault_bits=self.fault_bits[i],
                    fault_names=_FAULT_NAMES(self.fault_bits[i]),
                    heartbeat_age_s=(now - self._heard_ns[i]) * 1e-9,
                    setpoint_counter=self.applied_counter[i],
                )
                for i in range(ACTUATOR_COUNT)
            ),
            now,
        )

    def link_health(self) -> LinkHealth:
        return LinkHealth(self.bus_state, self.send_failures)

    # -- fault injection ---------------------------------------------------------------

    def silence(self, leg: int, silent: bool = True) -> None:
        """Stop (or resume) leg 1–6's heartbeat: its reports stop arriving."""
        self.silenced[leg - 1] = silent

    def inject_fault(self, leg: int, bits: int = 1) -> None:
        """Put leg 1–6 into FAULT with the given fault word (``firmware_proto.codec.Fault``
        bits; any other bit is reported too, named ``bit_N``); it holds its length."""
        self.states[leg - 1] = ActuatorState.FAULT
        self.fault_bits[leg - 1] = bits

    def press_estop(self) -> None:
        """The hardware E-stop chain: every actuator goes to ESTOP and holds."""
        self.states = [ActuatorState.ESTOP] * ACTUATOR_COUNT

    # -- model -------------------------------------------------------------------------

    def _sendable(self) -> bool:
        if self.fail_sends or self.bus_state in (BusState.BUS_OFF, BusState.DOWN):
            self.send_failures += 1
            return False
        return True

    def _apply(self, i: int, command: ActuatorCommand) -> None:
        state = self.states[i]
        if command is ActuatorCommand.ENABLE and state is ActuatorState.DISABLED:
            self.targets[i] = self.positions[i]
            self.states[i] = ActuatorState.ENABLED
        elif command is ActuatorCommand.DISABLE and state in (ActuatorState.ENABLED, ActuatorState.LOCKED):
            self.states[i] = ActuatorState.DISABLED
        elif command is ActuatorCommand.CLEAR_FAULT and state in (ActuatorState.FAULT, ActuatorState.ESTOP):
            if state is ActuatorState.ESTOP and self._estop_recent():
                return  # as the firmware: an E-stop clears only after none for the hold-off
            self.states[i] = ActuatorState.DISABLED
            self.fault_bits[i] = 0
        elif command is ActuatorCommand.LOCK and state is ActuatorState.ENABLED:
            self.states[i] = ActuatorState.LOCKED
        elif command is ActuatorCommand.UNLOCK and state is ActuatorState.LOCKED:
            self.targets[i] = self.positions[i]
            self.states[i] = ActuatorState.ENABLED

    def _estop_recent(self) -> bool:
        last = self._last_estop_ns
        return last is not None and self.clock_ns() - last < self.estop_clear_holdoff_ns

    def _advance(self) -> int:
        """Move every actuator to the clock's present; returns the present, ns."""
        now = self.clock_ns()
        dt = (now - self._last_ns) * 1e-9
        if dt > 0:
            blend = 1.0 - exp(-dt / self.lag_s) if self.lag_s > 0 else 1.0
            for i in range(ACTUATOR_COUNT):
                if self.states[i] in _HOLDING:
                    self.velocities[i] = 0.0
                    continue
                step = (self.targets[i] - self.positions[i]) * blend
                self.positions[i] += step
                self.velocities[i] = step / dt
            self._last_ns = now
        for i in range(ACTUATOR_COUNT):
            if not self.silenced[i]:
                self._heard_ns[i] = now
        return now
