"""One actuator's firmware, simulated: the protocol of ``firmware_proto`` (PROTOCOL.md) and a
drive that moves.

:class:`ActuatorFirmware` is deterministic and driven by time, with no threads and no clock of
its own: :meth:`~ActuatorFirmware.receive` takes one received frame and the time it arrived,
:meth:`~ActuatorFirmware.advance` moves the drive and runs the timers to a time; both return the
frames the actuator transmits in response (:data:`~firmware_proto.codec.CanFrame` tuples).
:mod:`hexactl.sim.actuator_bus` puts six of them on a CAN bus.

Units: µm, µm/s, µm/s² and seconds, as on the wire.

The drive: a first-order lag (time constant ``lag_s``) towards the applied set-point, with its
speed limited to ``max_velocity_um_s``, to what still stops at the set-point with
``max_acceleration_um_s2`` and to what still stops before the soft limits (limit braking), and
its acceleration limited to the same. A set-point that stops more abruptly than that is
overshot, as by a real drive. Outside ENABLED it makes a
controlled stop at that deceleration and then holds on its brake; in LOCKED the brake holds at
once. The sensor reads the position rounded to 1 µm.

What it implements of the protocol: the state machine of section 6 (INIT passes its self-test
at the first call), set-point latching at SETPOINT and application at SYNC (or at
SETPOINT_ALL_FD), counter freshness, the set-point rules of section 4 (soft limits and step ≤
speed limit × cycles × T), the timer watchdog of (N + ½)·T, the following-error limit, ESTOP
acted on by identifier alone, command sequences and acknowledgements, FEEDBACK on the SYNCs
``feedback_due`` selects, EMCY (at most one per 10 ms), HEARTBEAT every 100 ms with the count
of rejected frames.

Faults are injected through :attr:`ActuatorFirmware.inject` (:class:`FaultInjection`).
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from math import ceil, copysign, sqrt

from firmware_proto.codec import (
    NODE_IDS,
    STROKE_MAX_UM,
    STROKE_MIN_UM,
    WATCHDOG_CYCLES_MAX,
    WATCHDOG_CYCLES_MIN,
    ActuatorState,
    CanFrame,
    Command,
    CommandCode,
    CommandResult,
    EStopReason,
    Fault,
    FaultCode,
    FrameError,
    FrameId,
    LoopRate,
    NodeFrameBase,
    decode_command,
    decode_estop,
    decode_setpoint_frame,
    decode_setpoints_fd,
    decode_sync,
    encode_command_ack,
    encode_emergency,
    encode_feedback,
    encode_heartbeat,
    feedback_due,
    is_fresh_counter,
)

_SETPOINT_FRAME_OF_NODE = {
    1: FrameId.SETPOINT_12, 2: FrameId.SETPOINT_12,
    3: FrameId.SETPOINT_34, 4: FrameId.SETPOINT_34,
    5: FrameId.SETPOINT_56, 6: FrameId.SETPOINT_56,
}  # fmt: skip
_VALID_LOOP_RATES = (LoopRate.HZ_250, LoopRate.HZ_500, LoopRate.HZ_1000)
_ENGAGED = (ActuatorState.ENABLED, ActuatorState.LOCKED)
_HEARTBEAT_REJECTED_MAX = 0xFF


@dataclass(frozen=True, slots=True)
class ActuatorParams:
    """A simulated actuator's configuration (µm, µm/s, µm/s², s).

    :ivar soft_limits_um: set-points outside ``[low, high]`` are refused, and the drive brakes
        so that it never passes them
    :ivar max_velocity_um_s: speed limit of the drive and of the set-point step rule
    :ivar max_acceleration_um_s2: acceleration limit, also the controlled-stop deceleration
    :ivar lag_s: time constant of the drive's first-order lag
    :ivar following_error_limit_um: ``|target − position|`` above this latches FOLLOWING_ERROR
    :ivar heartbeat_period_s: HEARTBEAT period
    :ivar physics_step_s: longest integration step; longer intervals are split evenly
    :ivar initial_loop_rate: loop rate for the feedback schedule until the first ENABLE
    :ivar estop_clear_holdoff_s: CLEAR_FAULT leaves ESTOP only this long after the last ESTOP frame
    :ivar emergency_interval_s: at most one EMCY per this interval
    """

    soft_limits_um: tuple[int, int] = (STROKE_MIN_UM, STROKE_MAX_UM)
    max_velocity_um_s: float = 400_000.0
    max_acceleration_um_s2: float = 10_000_000.0
    lag_s: float = 0.005
    following_error_limit_um: float = 25_000.0
    heartbeat_period_s: float = 0.100
    physics_step_s: float = 0.001
    initial_loop_rate: LoopRate = LoopRate.HZ_500
    estop_clear_holdoff_s: float = 0.250
    emergency_interval_s: float = 0.010

    def __post_init__(self) -> None:
        low, high = self.soft_limits_um
        if not low < high:
            raise ValueError(f"soft_limits_um: {low} must be below {high}")
        for name in ("max_velocity_um_s", "max_acceleration_um_s2", "lag_s", "following_error_limit_um",
                     "heartbeat_period_s", "physics_step_s"):  # fmt: skip
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        if self.initial_loop_rate not in _VALID_LOOP_RATES:
            raise ValueError(f"initial_loop_rate must be 250, 500 or 1000 Hz, got {self.initial_loop_rate!r}")


@dataclass(slots=True)
class FaultInjection:
    """Faults a test switches on and off while the firmware runs.

    Reception (frames addressed to this actuator: ESTOP, SYNC, its SETPOINT and CMD frames):

    :ivar drop_next: the next this many frames are lost (never seen)
    :ivar corrupt_next: the next this many frames arrive with one bit flipped (CRC fails)
    :ivar drop_probability: each further frame is lost with this probability
    :ivar corrupt_probability: each further frame is corrupted with this probability
    :ivar seed: seed of the generator behind the probabilities (reproducible runs)

    Behaviour:

    :ivar silent: the actuator transmits nothing (heartbeat, feedback, acks): it looks lost
    :ivar stall: the drive is jammed and does not move: a moving target trips FOLLOWING_ERROR
    :ivar sensor_fault: the sensor reports a fault: SENSOR latches and persists while set
    :ivar brake_slip_um_s: in LOCKED the brake slips: the leg creeps at this speed, µm/s (signed)
    """

    drop_next: int = 0
    corrupt_next: int = 0
    drop_probability: float = 0.0
    corrupt_probability: float = 0.0
    seed: int = 0
    silent: bool = False
    stall: bool = False
    sensor_fault: bool = False
    brake_slip_um_s: float = 0.0
    _random: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._random = random.Random(self.seed)

    def filter(self, payload: bytes) -> bytes | None:
        """The payload as this actuator receives it: None if lost, else possibly corrupted."""
        if self.drop_next > 0:
            self.drop_next -= 1
            return None
        if self.drop_probability and self._random.random() < self.drop_probability:
            return None
        if self.corrupt_next > 0:
            self.corrupt_next -= 1
            return _flip_bit(payload)
        if self.corrupt_probability and self._random.random() < self.corrupt_probability:
            return _flip_bit(payload)
        return payload


def _flip_bit(payload: bytes) -> bytes:
    if not payload:
        return payload
    return bytes((payload[0] ^ 0x01,)) + payload[1:]


class ActuatorFirmware:
    """The firmware of actuator ``node`` (1..6), its drive starting at rest at ``position_um``.

    Time ``t_s`` (seconds, any origin, never decreasing) starts at ``start_s``. The firmware is
    in INIT until the first :meth:`advance` or :meth:`receive`, where its self-test passes and it
    announces itself with a HEARTBEAT in DISABLED.

    :raises ValueError: for a node outside 1..6 or a start position outside the soft limits
    """

    def __init__(
        self,
        node: int,
        position_um: float,
        params: ActuatorParams = ActuatorParams(),
        *,
        start_s: float = 0.0,
        inject: FaultInjection | None = None,
    ) -> None:
        if node not in NODE_IDS:
            raise ValueError(f"node {node!r} is not one of 1..6")
        low, high = params.soft_limits_um
        if not low <= position_um <= high:
            raise ValueError(f"start position {position_um} µm outside the soft limits [{low}, {high}]")
        self.node = node
        self.params = params
        self.inject = inject if inject is not None else FaultInjection()
        self.state = ActuatorState.INIT
        self.faults = Fault(0)
        self.position_um = float(position_um)
        self.velocity_um_s = 0.0
        self.target_um = float(position_um)
        self.setpoint_counter = 0
        self.rejected_total = 0
        self.loop_rate = params.initial_loop_rate
        self.watchdog_cycles = 0
        self._t = start_s
        self._rejected_since_heartbeat = 0
        self._heartbeat_counter = 0
        self._next_heartbeat_s = start_s
        self._last_counter: int | None = None  # of the last applied set-point; None after ENABLE
        self._latched: tuple[int, int] | None = None  # (counter, set-point µm) awaiting its SYNC
        self._watchdog_deadline_s = 0.0
        self._last_command: tuple[int, CommandResult] | None = None  # (sequence, result)
        self._last_estop_s = -float("inf")
        self.last_estop_reason: EStopReason | None = None  # logged from the last ESTOP (None: none, or unreadable)
        self._last_emergency_s = -float("inf")
        self._setpoint_frame_id = _SETPOINT_FRAME_OF_NODE[node]
        self._command_frame_id = NodeFrameBase.CMD + node

    # -- inputs --------------------------------------------------------------------------

    @property
    def sensor_um(self) -> int:
        """The position sensor's reading, µm (quantised to 1 µm)."""
        return round(self.position_um)

    def advance(self, t_s: float) -> list[CanFrame]:
        """Move the drive and run the timers (watchdog, heartbeat) up to ``t_s``; the frames to send."""
        out: list[CanFrame] = []
        self._run_to(t_s, out)
        return [] if self.inject.silent else out

    def receive(self, can_id: int, payload: bytes, t_s: float) -> list[CanFrame]:
        """Process one frame received at ``t_s`` (after advancing to it); the frames to send.

        Frames not addressed to this actuator are ignored; frames it must reject (section 5)
        are counted for the next HEARTBEAT and change nothing.
        """
        out: list[CanFrame] = []
        self._run_to(t_s, out)
        if can_id == FrameId.ESTOP:
            if (received := self.inject.filter(bytes(payload))) is not None:  # a lost one is not seen; any payload counts
                self._on_estop(t_s, out)
                self.last_estop_reason = decode_estop(can_id, received).reason
        elif can_id in (FrameId.SYNC, self._setpoint_frame_id, self._command_frame_id, FrameId.SETPOINT_ALL_FD):
            received = self.inject.filter(bytes(payload))
            if received is not None:
                try:
                    self._dispatch(can_id, received, t_s, out)
                except FrameError:
                    self._reject()
        return [] if self.inject.silent else out

    # -- frame handling ------------------------------------------------------------------

    def _dispatch(self, can_id: int, payload: bytes, t_s: float, out: list[CanFrame]) -> None:
        if can_id == FrameId.SYNC:
            self._on_sync(decode_sync(can_id, payload).counter, t_s, out)
        elif can_id == self._setpoint_frame_id:
            frame = decode_setpoint_frame(can_id, payload)
            self._latch(frame.counter, frame.positions_um[self.node - frame.first_node])
        elif can_id == self._command_frame_id:
            self._on_command(decode_command(can_id, payload), t_s, out)
        else:  # SETPOINT_ALL_FD: its own SYNC (section 11)
            frame = decode_setpoints_fd(can_id, payload)
            if self._latch(frame.counter, frame.positions_um[self.node - 1]):
                self._on_sync(frame.counter, t_s, out)

    def _reject(self) -> None:
        self.rejected_total += 1
        self._rejected_since_heartbeat += 1

    def _fresh(self, counter: int) -> bool:
        last = self._last_counter
        return last is None or is_fresh_counter(counter, last, self.watchdog_cycles)

    def _latch(self, counter: int, setpoint_um: int) -> bool:
        """Latch a set-point for the SYNC with ``counter``; False if the frame was rejected."""
        if self.state in _ENGAGED:
            if not self._fresh(counter):
                self._reject()
                return False
            self._latched = (counter, setpoint_um)
        return True

    def _on_sync(self, counter: int, t_s: float, out: list[CanFrame]) -> None:
        if self.state in _ENGAGED:
            if not self._fresh(counter):
                self._reject()
                return
            latched, self._latched = self._latched, None
            if latched is not None and latched[0] == counter:
                self._apply(counter, latched[1], t_s, out)
            # else: a missed cycle — the target stays and the watchdog keeps running
        if feedback_due(self.node, counter, self.loop_rate):
            out.append(
                encode_feedback(
                    self.node, self.sensor_um, self.velocity_um_s, self.state, self.faults, self.setpoint_counter
                )
            )

    def _apply(self, counter: int, setpoint_um: int, t_s: float, out: list[CanFrame]) -> None:
        if self.state is ActuatorState.ENABLED:
            low, high = self.params.soft_limits_um
            cycles = 1 if self._last_counter is None else (counter - self._last_counter) & 0xFF
            # +1 µm: set-point and target are each rounded to the µm
            largest_step = self.params.max_velocity_um_s * cycles / self.loop_rate + 1.0
            if not low <= setpoint_um <= high or abs(setpoint_um - self.target_um) > largest_step:
                self._latch_fault(FaultCode.SETPOINT_RANGE, t_s, out)
                return
            self.target_um = float(setpoint_um)
        # In LOCKED the set-point, a fresh frame, is counted but not applied: the brake holds the leg.
        self._last_counter = counter
        self.setpoint_counter = counter
        self._restart_watchdog(t_s)

    def _restart_watchdog(self, t_s: float) -> None:
        self._watchdog_deadline_s = t_s + (self.watchdog_cycles + 0.5) / self.loop_rate

    def _on_estop(self, t_s: float, out: list[CanFrame]) -> None:
        self._last_estop_s = t_s
        self._latch_fault(FaultCode.ESTOP, t_s, out)

    def _on_command(self, command: Command, t_s: float, out: list[CanFrame]) -> None:
        last = self._last_command
        if last is not None and last[0] == command.sequence:
            result = last[1]  # a retry: acknowledged again, not executed again
        else:
            result = self._execute(command, t_s, out)
            self._last_command = (command.sequence, result)
        out.append(encode_command_ack(self.node, command.command, command.sequence, result, self.state))

    def _execute(self, command: Command, t_s: float, out: list[CanFrame]) -> CommandResult:
        """The transition table of PROTOCOL.md section 6."""
        state, code = self.state, command.command
        if code is CommandCode.ENABLE and state is ActuatorState.DISABLED:
            if (
                command.loop_rate not in _VALID_LOOP_RATES
                or not WATCHDOG_CYCLES_MIN <= command.watchdog_cycles <= WATCHDOG_CYCLES_MAX
            ):
                return CommandResult.REJECTED_ARGUMENT
            self.loop_rate = command.loop_rate
            self.watchdog_cycles = command.watchdog_cycles
            self._last_counter = None
            self._latched = None
            self._follow_from_here()
            self.state = ActuatorState.ENABLED
            self._restart_watchdog(t_s)
            return CommandResult.ACCEPTED
        if code is CommandCode.DISABLE and state is not ActuatorState.INIT:
            if state in _ENGAGED:
                self.state = ActuatorState.DISABLED  # the drive makes a controlled stop
            return CommandResult.ACCEPTED
        if code is CommandCode.LOCK and state in _ENGAGED:
            self.state = ActuatorState.LOCKED
            self.velocity_um_s = 0.0  # the brake holds the leg where it is
            return CommandResult.ACCEPTED
        if code is CommandCode.UNLOCK and state is ActuatorState.LOCKED:
            self._follow_from_here()
            self.state = ActuatorState.ENABLED
            return CommandResult.ACCEPTED
        if code is CommandCode.CLEAR_FAULT and state is not ActuatorState.INIT:
            if state not in (ActuatorState.FAULT, ActuatorState.ESTOP):
                return CommandResult.ACCEPTED
            if self._fault_causes(t_s):
                return CommandResult.REJECTED_FAULT_ACTIVE
            self.faults = Fault(0)
            self.state = ActuatorState.DISABLED
            self._emergency(FaultCode.NONE, t_s, out, rate_limited=False)
            return CommandResult.ACCEPTED
        return CommandResult.REJECTED_STATE

    def _follow_from_here(self) -> None:
        """Bumpless start: the previous target is the measured position (section 4)."""
        self.target_um = float(self.sensor_um)

    def _fault_causes(self, t_s: float) -> bool:
        """Whether a cause of a latched fault persists (CLEAR_FAULT is then refused)."""
        if self.state is ActuatorState.ESTOP and t_s - self._last_estop_s < self.params.estop_clear_holdoff_s:
            return True
        return self.inject.sensor_fault

    def _latch_fault(self, code: FaultCode, t_s: float, out: list[CanFrame]) -> None:
        """Latch a fault: controlled stop, FAULT (ESTOP wins), EMCY if newly latched."""
        new = not self.faults & code.flag
        self.faults |= code.flag
        if code is FaultCode.ESTOP:
            self.state = ActuatorState.ESTOP
        elif self.state is not ActuatorState.ESTOP:
            self.state = ActuatorState.FAULT
        self._latched = None
        if new:
            self._emergency(code, t_s, out, rate_limited=True)

    def _emergency(self, code: FaultCode, t_s: float, out: list[CanFrame], *, rate_limited: bool) -> None:
        if rate_limited and t_s - self._last_emergency_s < self.params.emergency_interval_s:
            return  # the fault shows in the next EMCY's and every FEEDBACK's fault bits
        self._last_emergency_s = t_s
        out.append(encode_emergency(self.node, code, self.state, self.faults))

    # -- time ----------------------------------------------------------------------------

    def _run_to(self, t_s: float, out: list[CanFrame]) -> None:
        if self.state is ActuatorState.INIT:
            self.state = ActuatorState.DISABLED  # self-test passed
        span = t_s - self._t
        if span > 0:
            steps = ceil(span / self.params.physics_step_s)
            dt = span / steps
            start = self._t
            for index in range(1, steps + 1):
                now = start + index * dt
                self._physics_step(dt, now, out)
                if self.state in _ENGAGED and now >= self._watchdog_deadline_s:
                    self._latch_fault(FaultCode.COMM_TIMEOUT, now, out)
            self._t = t_s
        if self.inject.sensor_fault and not self.faults & Fault.SENSOR:
            self._latch_fault(FaultCode.SENSOR, self._t, out)
        if self._t >= self._next_heartbeat_s:
            out.append(
                encode_heartbeat(
                    self.node,
                    self.state,
                    self._heartbeat_counter,
                    rejected_frames=min(self._rejected_since_heartbeat, _HEARTBEAT_REJECTED_MAX),
                )
            )
            self._heartbeat_counter = (self._heartbeat_counter + 1) & 0xFF
            self._rejected_since_heartbeat = 0
            period = self.params.heartbeat_period_s
            # Stay on the period grid; after a long gap send one heartbeat, not a burst.
            self._next_heartbeat_s += period * max(1, ceil((self._t - self._next_heartbeat_s) / period))

    def _physics_step(self, dt: float, now: float, out: list[CanFrame]) -> None:
        params = self.params
        accel = params.max_acceleration_um_s2
        velocity = self.velocity_um_s
        if self.state is ActuatorState.LOCKED:
            velocity = self.inject.brake_slip_um_s
        elif self.inject.stall:
            velocity = 0.0
        else:
            if self.state is ActuatorState.ENABLED:
                error = self.target_um - self.position_um
                # Fast enough to follow with the lag, never faster than the speed limit or
                # than what can still stop at the target.
                speed = min(abs(error) / params.lag_s, params.max_velocity_um_s, sqrt(2.0 * accel * abs(error)))
                wanted = copysign(speed, error)
            else:
                wanted = 0.0  # controlled stop, then the brake holds
            change = wanted - velocity
            limit = accel * dt
            velocity += max(-limit, min(limit, change))
        low, high = params.soft_limits_um
        # Like a drive's limit braking: never faster than what still stops before the end
        # stop at full deceleration, and never past it within one step.
        room = high - self.position_um if velocity > 0 else self.position_um - low
        room = max(room, 0.0)
        speed = min(abs(velocity), sqrt(2.0 * accel * room), room / dt)
        velocity = copysign(speed, velocity)
        # The clamp only absorbs floating-point rounding of room / dt · dt.
        position = min(max(self.position_um + velocity * dt, low), high)
        self.position_um = position
        self.velocity_um_s = velocity
        if (
            self.state is ActuatorState.ENABLED
            and abs(self.target_um - position) > params.following_error_limit_um
        ):
            self._latch_fault(FaultCode.FOLLOWING_ERROR, now, out)
