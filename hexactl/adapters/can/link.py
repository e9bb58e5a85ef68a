"""The controller's CAN link: :class:`CanActuatorLink` implements the control layer's
:class:`~hexactl.control.hardware.ActuatorInterface` over python-can with the actuator protocol
of ``firmware_proto`` (PROTOCOL.md; frames are built and parsed only by its codec).

Units at this interface are those of :mod:`hexactl.control.hardware` (sensor mm, mm/s, s);
on the wire they are µm and µm/s, rounded to the nearest µm.

Sending never blocks and never queues: every frame goes out with ``timeout=0`` (the E-stop
with a short bounded timeout) and a frame that cannot be sent is dropped and counted in
:attr:`LinkHealth.send_failures`. A cycle whose set-point frame fails is abandoned before its
SYNC, so no actuator applies part of it and nothing stale is ever sent later. Commands are
the only frames that are repeated: unacknowledged commands are retried with the same
sequence number (PROTOCOL.md section 7), which the actuator executes at most once.

The cycle never stops: SYNC schedules every actuator's FEEDBACK in every state (PROTOCOL.md
section 4), so when no cycle was sent since the previous :meth:`CanActuatorLink.read_feedback`
(a loop that does not know the positions yet, or refused set-points) that call sends a bare
SYNC. It carries no set-point: an enabled actuator counts it a missed cycle and its watchdog
keeps running. Its counter follows the last one sent, so it never completes a half-sent cycle.

Receiving happens in :meth:`CanActuatorLink.read_feedback`: it drains at most
``max_frames_per_read`` frames with ``recv(timeout=0)``, decodes FEEDBACK, HEARTBEAT, EMCY and
CMD_ACK into per-actuator state (position and velocity are NaN until an actuator's first
FEEDBACK), counts every frame the codec rejects (bad DLC, CRC or
value, unknown id) instead of raising, names the reason for an actuator's in
:attr:`LinkHealth.detail`, and notes when another controller's frame (set-points,
SYNC, a command; not an E-stop) was last heard, for :meth:`CanActuatorLink.link_health`.
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import inf, nan

import can

from firmware_proto.codec import (
    NODE_IDS,
    PROTOCOL_VERSION,
    WATCHDOG_CYCLES_DEFAULT,
    WATCHDOG_CYCLES_MAX,
    WATCHDOG_CYCLES_MIN,
    CommandAck,
    CommandCode,
    CommandResult,
    Emergency,
    EStop,
    EStopReason,
    Fault,
    Feedback,
    FrameError,
    Heartbeat,
    LoopRate,
    NodeFrameBase,
    SetpointFrame,
    SetpointsFd,
    Sync,
    decode,
    encode_command,
    encode_estop,
    encode_setpoints,
    encode_sync,
)
from firmware_proto.codec import ActuatorState as WireState
from hexactl.adapters.can.socketcan_bus import BatchSendError, LeanSocketcanBus
from hexactl.adapters.can.transport import (
    BusSpec,
    bus_state_after_send_error,
    bus_state_from_error_frame,
    open_bus,
)
from hexactl.control.hardware import (
    ActuatorCommand,
    ActuatorFeedback,
    ActuatorState,
    BusState,
    EstopCause,
    FaultNames,
    FeedbackSnapshot,
    LinkHealth,
)

_UM_PER_MM = 1000.0  # dividing by it, not multiplying by 1e-3, gives the double nearest the decimal mm

STATE_FROM_WIRE: dict[WireState, ActuatorState] = {
    WireState.INIT: ActuatorState.DISABLED,  # booting: not following, brake on
    WireState.DISABLED: ActuatorState.DISABLED,
    WireState.ENABLED: ActuatorState.ENABLED,
    WireState.LOCKED: ActuatorState.LOCKED,
    WireState.FAULT: ActuatorState.FAULT,
    WireState.ESTOP: ActuatorState.ESTOP,
}
"""Firmware state → control-layer state."""

ESTOP_REASON: dict[EstopCause, EStopReason] = {
    EstopCause.OPERATOR: EStopReason.OPERATOR,
    EstopCause.SAFETY_CHAIN: EStopReason.SAFETY_CHAIN,
    EstopCause.CONTROLLER_FAULT: EStopReason.CONTROLLER_FAULT,
}
"""Why the controller stops them → the ESTOP frame's Reason."""

COMMAND_TO_WIRE: dict[ActuatorCommand, CommandCode] = {
    ActuatorCommand.ENABLE: CommandCode.ENABLE,
    ActuatorCommand.DISABLE: CommandCode.DISABLE,
    ActuatorCommand.CLEAR_FAULT: CommandCode.CLEAR_FAULT,
    ActuatorCommand.LOCK: CommandCode.LOCK,
    ActuatorCommand.UNLOCK: CommandCode.UNLOCK,
}
"""Control-layer command → protocol command."""

FAULT_NAMES = FaultNames(Fault)
"""The fault bits' names (PROTOCOL.md section 9), from the codec's definition of them."""

_ENGAGED = (WireState.ENABLED, WireState.LOCKED)
_AT_REST = (WireState.DISABLED, WireState.FAULT, WireState.ESTOP)  # where DISABLE changes nothing
_LOOP_RATES = (LoopRate.HZ_250, LoopRate.HZ_500, LoopRate.HZ_1000)

# Another controller's frames as LinkHealth.other_controller_frame names them; made once, so
# that a controller streaming beside this one costs a look-up per frame, not a string.
_SETPOINT_NAMES = {first: f"SETPOINT_{first}{first + 1}" for first in (1, 3, 5)}
_COMMAND_NAMES = {(node, code): f"CMD_{node} {code.name}" for node in NODE_IDS for code in CommandCode}
# The leg that sends each actuator frame, to name it when the codec rejects one of its frames.
_SENDER = {base + node: node for base in (NodeFrameBase.EMCY, NodeFrameBase.FEEDBACK, NodeFrameBase.CMD_ACK,
                                          NodeFrameBase.HEARTBEAT) for node in NODE_IDS}


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """How the link drives the actuators.

    :ivar loop_rate: the control loop's rate, sent with every ENABLE
    :ivar watchdog_cycles: loop cycles without a valid set-point before an actuator stops with
        COMM_TIMEOUT, sent with every ENABLE (3..100)
    :ivar heartbeat_timeout_s: an actuator that sent nothing for this long is reported silent
        in :meth:`CanActuatorLink.link_health` (the link's diagnostic; the loop's supervision decides, PROTOCOL.md section 7)
    :ivar max_frames_per_read: bound on the frames one :meth:`CanActuatorLink.read_feedback` drains
    :ivar command_retry_s: a command unacknowledged for this long is sent again (same sequence)
    :ivar command_retries: retries before the command is given up and counted as timed out
    :ivar estop_send_timeout_s: how long :meth:`CanActuatorLink.send_estop` may wait for room
        in the transmit queue (the only send that waits at all)
    """

    loop_rate: LoopRate = LoopRate.HZ_500
    watchdog_cycles: int = WATCHDOG_CYCLES_DEFAULT
    heartbeat_timeout_s: float = 0.3
    max_frames_per_read: int = 256
    command_retry_s: float = 0.020
    command_retries: int = 3
    estop_send_timeout_s: float = 0.005

    def __post_init__(self) -> None:
        if self.loop_rate not in _LOOP_RATES:
            raise ValueError(f"loop_rate must be 250, 500 or 1000 Hz, got {self.loop_rate!r}")
        if not WATCHDOG_CYCLES_MIN <= self.watchdog_cycles <= WATCHDOG_CYCLES_MAX:
            raise ValueError(
                f"watchdog_cycles must be {WATCHDOG_CYCLES_MIN}..{WATCHDOG_CYCLES_MAX}, got {self.watchdog_cycles}"
            )
        if self.max_frames_per_read < 1:
            raise ValueError("max_frames_per_read must be at least 1")


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counters since the link was opened (diagnostics; the loop needs only :class:`LinkHealth`).

    :ivar frames_received: frames taken from the bus
    :ivar undecodable_frames: frames the codec rejected (bad DLC, CRC, value or unknown id)
        and frames that are not classic 11-bit data frames
    :ivar foreign_frames: valid protocol frames that actuators do not send (another controller's,
        an E-stop from a safety PLC or an E-stop node; :class:`LinkHealth` says when another
        controller's was last heard)
    :ivar refused_setpoints: :meth:`CanActuatorLink.send_setpoints` calls refused before
        sending (non-finite or unencodable values); also counted as send failures
    :ivar send_failures: as in :class:`LinkHealth`
    :ivar command_timeouts: commands given up after their retries
    :ivar rejected_frames: per leg 1–6, the sum of the heartbeats' RejectedFrames
    :ivar emergencies: per leg 1–6, EMCY frames received
    """

    frames_received: int
    undecodable_frames: int
    foreign_frames: int
    refused_setpoints: int
    send_failures: int
    command_timeouts: int
    rejected_frames: tuple[int, ...]
    emergencies: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class NodeStatus:
    """Protocol-level view of one actuator (diagnostics).

    :ivar protocol_version: from its last HEARTBEAT, None before the first
    :ivar heartbeat_age_s: time since its last HEARTBEAT, s (``inf`` if none)
    :ivar feedback_age_s: time since its last FEEDBACK, s (``inf`` if none)
    :ivar last_ack: its last CMD_ACK, None before the first
    :ivar last_emergency: its last EMCY, None before the first
    :ivar command_pending: a command is waiting for its acknowledgement
    :ivar restarts: how often it started again since the link opened (its HEARTBEAT counter
        began again at 0, or it reported INIT after another state): a power or watchdog reset
    """

    protocol_version: int | None
    heartbeat_age_s: float
    feedback_age_s: float
    last_ack: CommandAck | None
    last_emergency: Emergency | None
    command_pending: bool
    restarts: int = 0


class _PendingCommand:
    __slots__ = ("code", "frame", "sequence", "sent_ns", "retries")

    def __init__(self, code: CommandCode, frame: tuple[int, bytes], sequence: int, sent_ns: int) -> None:
        self.code = code
        self.frame = frame
        self.sequence = sequence
        self.sent_ns = sent_ns
        self.retries = 0


class _Node:
    """What the link knows about one actuator."""

    __slots__ = (
        "position_mm", "velocity_mm_s", "wire_state", "fault_bits", "setpoint_counter", "enable_floor",
        "heard_ns", "heartbeat_ns", "heartbeat_counter", "restarts", "feedback_ns", "protocol_version",
        "rejected_frames", "emergencies", "last_emergency", "emergency_read", "last_ack", "sequence", "commanded", "pending",
    )  # fmt: skip

    def __init__(self) -> None:
        # NaN until the first FEEDBACK: no reading is better than a plausible-looking 0.0.
        self.position_mm = nan
        self.velocity_mm_s = nan
        self.wire_state = WireState.INIT
        self.fault_bits = 0
        self.setpoint_counter = -1  # unwrapped at its FEEDBACK; −1 outside ENABLED/LOCKED, or none of ours yet
        # The last counter sent before this link's latest ENABLE to it: an echo of it or an older
        # one is the actuator's from before its present enabling (its last session's, 0 after a reboot).
        self.enable_floor = -1
        self.heard_ns: int | None = None
        self.heartbeat_ns: int | None = None
        self.heartbeat_counter: int | None = None  # of its last HEARTBEAT
        self.restarts = 0
        self.feedback_ns: int | None = None
        self.protocol_version: int | None = None
        self.rejected_frames = 0
        self.emergencies = 0
        self.last_emergency: Emergency | None = None
        self.emergency_read = -1  # the read its last EMCY came in
        self.last_ack: CommandAck | None = None
        # An actuator that outlives a controller restart takes a first command whose sequence
        # equals its last executed one for a retry, and does not carry it out (PROTOCOL.md §5):
        # a random start, and the first command goes behind one that takes that risk (_send_command).
        self.sequence = random.randrange(256)
        self.commanded = False  # whether this link has sent it a command
        self.pending: _PendingCommand | None = None


class CanActuatorLink:
    """The six actuators over CAN, as an :class:`~hexactl.control.hardware.ActuatorInterface`.

    The link takes ownership of ``bus`` (:meth:`close` shuts it down). ``clock_ns`` is the
    time source for ages and retries (``time.monotonic_ns`` by default; tests pass their own).

    Threading: as the interface requires, only :meth:`send_estop` may be called from another
    thread than the loop's. A SocketCAN ``send`` is one ``send(2)`` per frame, a cycle's batch
    one ``sendmmsg(2)``, and the in-process buses' puts into thread-safe queues, so frames need
    no lock; the shared failure counters take one.
    """

    def __init__(
        self,
        bus: can.BusABC,
        config: LinkConfig = LinkConfig(),
        *,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        self._bus = bus
        self._send_batch = bus.send_batch if isinstance(bus, LeanSocketcanBus) else None
        self.config = config
        self._clock_ns = clock_ns
        self._nodes = tuple(_Node() for _ in NODE_IDS)
        self._lock = threading.Lock()
        self._bus_state = BusState.ACTIVE
        self._closed = False
        self._detail = ""
        self._send_failures = 0
        self._refused_setpoints = 0
        self._frames_received = 0
        self._undecodable = 0
        self._foreign = 0
        self._other_ns: int | None = None  # when another controller's frame was last heard
        self._other_frame = ""
        self._stray: tuple[int, int] | None = None  # (node id, when): our heartbeat from a node no leg has
        self._behind_ns: int | None = None  # when a read last left frames waiting (it drains a bounded number)
        self._reads = 0  # read_feedback calls: which read a frame came in
        self._bus_off_read = -1  # the read a bus-off error frame last came in
        self._command_timeouts = 0
        self._first_counter: int | None = None
        self._last_counter: int | None = None
        self._next_sync_counter = 0  # wire counter of the next bare SYNC
        self._cycle_sent = False  # a cycle went to the bus since the last read_feedback
        self._estop_frames = {cause: encode_estop(reason) for cause, reason in ESTOP_REASON.items()}

    @classmethod
    def open(cls, spec: str | BusSpec, config: LinkConfig = LinkConfig(), **bus_options: object) -> CanActuatorLink:
        """Open the bus named by ``spec`` (see :mod:`hexactl.adapters.can.transport`) and a link on it.

        :raises BusSpecError: for a malformed spec
        :raises can.CanError: if the bus cannot be opened
        """
        return cls(open_bus(spec, **bus_options), config)

    def close(self) -> None:
        """Shut the bus down; afterwards every send fails and the bus state is ``DOWN``."""
        self._closed = True
        self._bus_state = BusState.DOWN
        self._bus.shutdown()

    def __enter__(self) -> CanActuatorLink:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- ActuatorInterface -------------------------------------------------------------

    def send_setpoints(self, counter: int, setpoints_mm: Sequence[float]) -> bool:
        """Send one cycle: SETPOINT_12, SETPOINT_34, SETPOINT_56 and SYNC with ``counter`` mod 256.

        Set-points are sensor mm, rounded to the nearest µm. Refused without sending anything
        (False, counted in :attr:`LinkStats.refused_setpoints` and as a send failure): not six
        values, a NaN or infinite value, one outside the encodable ±8388 mm. Values outside the
        stroke but encodable are sent: the actuator refuses them (fault SETPOINT_RANGE).
        If a frame cannot be sent the rest of the cycle, SYNC included, is dropped (False).
        """
        try:
            frames = encode_setpoints(counter & 0xFF, [round(value * _UM_PER_MM) for value in setpoints_mm])
        except (ValueError, OverflowError, TypeError) as error:
            # round() raises ValueError for NaN and OverflowError for ±inf; the codec raises
            # ValueError for a count other than six or a value outside its field.
            with self._lock:
                self._refused_setpoints += 1
                self._send_failures += 1
                self._detail = f"set-points refused: {error}"
            return False
        self._cycle_sent = True
        self._next_sync_counter = (counter + 1) & 0xFF
        if not self._send_cycle(frames):
            return False
        if self._first_counter is None:
            self._first_counter = counter
        self._last_counter = counter
        return True

    def send_command(self, leg: int | None, command: ActuatorCommand) -> bool:
        """Send ``command`` to leg 1–6, or to each of the six when ``leg`` is None.

        ENABLE carries the configured loop rate and watchdog cycles, and is refused (False,
        counted as a send failure) for a leg that has not yet sent a HEARTBEAT with this
        protocol version. Unacknowledged commands are retried by :meth:`read_feedback`.
        Returns False if any of the frames could not be sent.
        """
        if leg is not None and leg not in NODE_IDS:
            return self._refuse(f"no leg {leg!r}: legs are 1-6")
        code = COMMAND_TO_WIRE.get(command)
        if code is None:
            return self._refuse(f"unknown command {command!r}")
        now = self._clock_ns()
        sent = True
        for node in NODE_IDS if leg is None else (leg,):
            sent = self._send_command(node, code, now) and sent
        return sent

    def send_estop(self, cause: EstopCause = EstopCause.OPERATOR) -> bool:
        """Send ESTOP, its Reason ``cause`` (:data:`ESTOP_REASON`; informative, for the
        actuators' logs). Safe from any thread; waits at most ``estop_send_timeout_s`` for
        room in the transmit queue. Call it again while the e-stop condition lasts
        (PROTOCOL.md: every 100 ms)."""
        can_id, payload = self._estop_frames[cause]
        return self._send(can_id, payload, self.config.estop_send_timeout_s)

    def read_feedback(self) -> FeedbackSnapshot:
        """Drain up to ``max_frames_per_read`` received frames, retry unacknowledged commands,
        send a bare SYNC if no cycle was sent since the last call, and return every actuator's
        latest report. Never waits and never raises."""
        now = self._clock_ns()
        self._reads += 1
        if not self._closed:
            if not self._cycle_sent:
                self._send(*encode_sync(self._next_sync_counter), 0.0)
                self._next_sync_counter = (self._next_sync_counter + 1) & 0xFF
            self._cycle_sent = False
            recv = self._bus.recv
            handle = self._handle
            for _ in range(self.config.max_frames_per_read):
                try:
                    message = recv(0.0)
                except Exception as error:  # the interface promises not to raise: report the bus down
                    self._bus_state = BusState.DOWN
                    self._detail = f"receive failed: {error}"
                    break
                if message is None:
                    break
                handle(message, now)
            else:
                self._behind_ns = now
            self._retry_commands(now)
        return FeedbackSnapshot(tuple(self._feedback(node, now) for node in self._nodes), now)

    def link_health(self) -> LinkHealth:
        """Bus state, send failures and a note naming any silent legs, any speaking another
        protocol version, and the last error (a send, a command given up or refused, an
        actuator's frame rejected)."""
        notes = []
        if silent := self.silent_legs():
            notes.append("silent legs: " + ", ".join(str(leg) for leg in silent))
            if (stray := self._stray_node()) is not None:
                notes.append(f"an actuator answers as node {stray} (its heartbeat, id 0x{NodeFrameBase.HEARTBEAT + stray:03X}), "
                             "which is no leg: set its node id to the silent leg's (1–6, one each)")
        for leg, node in zip(NODE_IDS, self._nodes):
            # Heard, yet reported absent to the loop (heartbeat_age_s inf): say why.
            if node.protocol_version not in (None, PROTOCOL_VERSION):
                notes.append(f"leg {leg} speaks protocol version {node.protocol_version}, this controller "
                             f"{PROTOCOL_VERSION}: it is not enabled while it does")
        if self._behind_ns is not None and self._recent(self._behind_ns):
            notes.append(f"receiving behind: a read found {self.config.max_frames_per_read} frames or more waiting, "
                         "so what the actuators report reaches the loop late (the loop held up, or a flood on the "
                         "bus: candump shows who sends)")
        if self._detail:
            notes.append(self._detail)
        other_ns = self._other_ns
        other_age_s = inf if other_ns is None else (self._clock_ns() - other_ns) * 1e-9
        state = self._bus_state
        if self._bus_off_read == self._reads and state is not BusState.BUS_OFF:
            # Back on the bus within the read: said all the same (frames were lost), as a
            # bus-off read last is (found from outside: a frame after it left no trace).
            state = BusState.BUS_OFF
            notes.append("bus-off in the last read, back on the bus since: frames were lost (wiring, termination, "
                         "bit rate: ip -details -statistics link show shows the error counters)")
        return LinkHealth(state, self._send_failures, "; ".join(notes), other_age_s, self._other_frame)

    # -- diagnostics -------------------------------------------------------------------

    def _stray_node(self) -> int | None:
        """The node id no leg has from which one of our actuators' heartbeats came within
        ``heartbeat_timeout_s`` (None: none). With a leg silent, an actuator set to a wrong
        node id is the likeliest cause; alone, it may be any device's: it is not named then."""
        if self._stray is None:
            return None
        node, heard_ns = self._stray
        return node if self._recent(heard_ns) else None

    def _recent(self, then_ns: int) -> bool:
        """``then_ns`` is within ``heartbeat_timeout_s`` of now: what the link's note still says."""
        return _age_s(then_ns, self._clock_ns()) <= self.config.heartbeat_timeout_s

    def silent_legs(self) -> tuple[int, ...]:
        """Legs from which nothing arrived for longer than ``heartbeat_timeout_s`` (as of
        the last :meth:`read_feedback`'s frames and the clock's present)."""
        now = self._clock_ns()
        limit = self.config.heartbeat_timeout_s
        return tuple(
            leg for leg, node in zip(NODE_IDS, self._nodes) if _age_s(node.heard_ns, now) > limit
        )

    def node_status(self, leg: int) -> NodeStatus:
        """Protocol-level state of leg 1–6.

        :raises ValueError: for a leg outside 1–6
        """
        if leg not in NODE_IDS:
            raise ValueError(f"no leg {leg!r}: legs are 1-6")
        node = self._nodes[leg - 1]
        now = self._clock_ns()
        return NodeStatus(
            node.protocol_version,
            _age_s(node.heartbeat_ns, now),
            _age_s(node.feedback_ns, now),
            node.last_ack,
            node.last_emergency,
            node.pending is not None,
            node.restarts,
        )

    def stats(self) -> LinkStats:
        """Counters since the link was opened."""
        return LinkStats(
            self._frames_received,
            self._undecodable,
            self._foreign,
            self._refused_setpoints,
            self._send_failures,
            self._command_timeouts,
            tuple(node.rejected_frames for node in self._nodes),
            tuple(node.emergencies for node in self._nodes),
        )

    # -- sending -----------------------------------------------------------------------

    def _send(self, can_id: int, payload: bytes, timeout_s: float) -> bool:
        try:
            self._bus.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False), timeout_s)
        except Exception as error:  # any failure, expected (CanOperationError) or not, is counted
            return self._send_failed(can_id, error)
        return self._sent()

    def _send_cycle(self, frames: Sequence[tuple[int, bytes]]) -> bool:
        """Send a cycle's frames in order, in one system call where the bus can batch them
        (:meth:`LeanSocketcanBus.send_batch`); stops at the first that cannot be sent."""
        if self._send_batch is None:
            return all(self._send(can_id, payload, 0.0) for can_id, payload in frames)
        try:
            self._send_batch([can.Message(arbitration_id=can_id, data=payload, is_extended_id=False)
                              for can_id, payload in frames])  # fmt: skip
        except BatchSendError as error:
            return self._send_failed(frames[error.sent][0], error)
        except Exception as error:  # as in _send
            return self._send_failed(frames[0][0], error)
        return self._sent()

    def _send_failed(self, can_id: int, error: Exception) -> bool:
        with self._lock:
            self._send_failures += 1
            self._bus_state = BusState.DOWN if self._closed else bus_state_after_send_error(error, self._bus_state)
            self._detail = f"send 0x{can_id:03X} failed: {error}"
        return False

    def _sent(self) -> bool:
        if self._bus_state is BusState.DOWN and not self._closed:
            self._bus_state = BusState.ACTIVE  # the interface is back
        return True

    def _refuse(self, reason: str) -> bool:
        with self._lock:
            self._send_failures += 1
            self._detail = reason
        return False

    def _send_command(self, leg: int, code: CommandCode, now: int) -> bool:
        node = self._nodes[leg - 1]
        if code is CommandCode.ENABLE and node.protocol_version != PROTOCOL_VERSION:
            heard = "no heartbeat yet" if node.protocol_version is None else f"protocol {node.protocol_version}"
            return self._refuse(f"ENABLE refused for leg {leg}: {heard}, need protocol {PROTOCOL_VERSION}")
        if not node.commanded and node.wire_state in _AT_REST:
            # Its last executed sequence, from before this link, may be any: one in 256 first
            # commands would be acknowledged and not carried out (an ENABLE after a restart left
            # the leg disabled). A DISABLE, which changes nothing at rest, takes that risk; the
            # command goes with the next sequence, which is then not the actuator's last.
            self._send(*encode_command(leg, CommandCode.DISABLE, node.sequence), 0.0)
            node.sequence = (node.sequence + 1) & 0xFF
        node.commanded = True
        if code is CommandCode.ENABLE:
            frame = encode_command(leg, code, node.sequence, self.config.loop_rate, self.config.watchdog_cycles)
            node.enable_floor = -1 if self._last_counter is None else self._last_counter
        else:
            frame = encode_command(leg, code, node.sequence)
        sequence = node.sequence
        node.sequence = (sequence + 1) & 0xFF
        # A newer command supersedes an unacknowledged older one, sent or not: only the latest
        # is retried, so an older ENABLE is never re-sent after a DISABLE that failed to send.
        node.pending = _PendingCommand(code, frame, sequence, now)
        return self._send(*frame, 0.0)

    def _retry_commands(self, now: int) -> None:
        retry_ns = int(self.config.command_retry_s * 1e9)
        for leg, node in zip(NODE_IDS, self._nodes):
            pending = node.pending
            if pending is None or now - pending.sent_ns < retry_ns:
                continue
            if pending.retries >= self.config.command_retries:
                node.pending = None
                self._command_timeouts += 1
                self._detail = f"leg {leg}: command {pending.code.name} not acknowledged after {pending.retries} retries"
                continue
            pending.retries += 1
            pending.sent_ns = now
            self._send(*pending.frame, 0.0)

    # -- receiving ---------------------------------------------------------------------

    def _handle(self, message: can.Message, now: int) -> None:
        self._frames_received += 1
        if message.is_error_frame:
            state = bus_state_from_error_frame(message)
            if state is not None:
                self._bus_state = state
                if state is BusState.BUS_OFF:
                    self._bus_off_read = self._reads
            return
        if self._bus_state is BusState.BUS_OFF:
            # A frame received proves the controller is back on the bus, whether or not the
            # driver's restart error frame arrived (a receive-buffer overrun loses it).
            self._bus_state = BusState.ACTIVE
        if message.is_extended_id or message.is_remote_frame:
            self._undecodable += 1
            return
        try:
            decoded = decode(message.arbitration_id, message.data)
        except FrameError as error:
            self._undecodable += 1
            # A leg whose frames are all rejected (a firmware of another DBC revision) looks
            # silent to the loop: say why, as the last error, where the enable refusal quotes it.
            if (leg := _SENDER.get(message.arbitration_id)) is not None:
                self._detail = f"leg {leg}'s frames rejected: {error}"
            elif (stray := _stray_heartbeat(message)) is not None:
                self._stray = stray, now
            return
        kind = type(decoded)
        if kind is Feedback:
            node = self._nodes[decoded.node - 1]
            node.position_mm = decoded.position_um / _UM_PER_MM
            node.velocity_mm_s = decoded.velocity_um_s / _UM_PER_MM
            if node.emergency_read != self._reads:
                node.wire_state = decoded.state
                node.fault_bits = int(decoded.faults)
            else:  # an EMCY in this read stands: a FEEDBACK after it in one read hid it from the loop (found from outside)
                node.fault_bits |= int(decoded.faults)
            node.setpoint_counter = self._unwrap(decoded.setpoint_counter, node.enable_floor)
            node.feedback_ns = now
        elif kind is Heartbeat:
            node = self._nodes[decoded.node - 1]
            self._note_heartbeat(decoded, node)
            node.heartbeat_counter = decoded.counter
            node.wire_state = decoded.state
            node.protocol_version = decoded.protocol_version
            node.rejected_frames += decoded.rejected_frames
            node.heartbeat_ns = now
        elif kind is Emergency:
            node = self._nodes[decoded.node - 1]
            node.wire_state = decoded.state
            node.fault_bits = int(decoded.faults)
            node.emergencies += 1
            node.last_emergency = decoded
            node.emergency_read = self._reads
        elif kind is CommandAck:
            node = self._nodes[decoded.node - 1]
            node.wire_state = decoded.state
            node.last_ack = decoded
            pending = node.pending
            if pending is not None and pending.sequence == decoded.sequence:
                node.pending = None
            if decoded.result is not CommandResult.ACCEPTED:
                self._detail = (
                    f"leg {decoded.node}: {decoded.command.name} {decoded.result.name} in {decoded.state.name}"
                )
        else:
            self._foreign += 1
            # Another controller drives the actuators too (this link does not hear its own
            # frames). An E-stop is no sign of one: a safety PLC or an E-stop node may send it.
            if kind is not EStop:
                self._other_ns = now
                if kind is Sync:
                    self._other_frame = "SYNC"
                elif kind is SetpointFrame:
                    self._other_frame = _SETPOINT_NAMES[decoded.first_node]
                elif kind is SetpointsFd:
                    self._other_frame = "SETPOINT_ALL_FD"
                else:
                    self._other_frame = _COMMAND_NAMES[decoded.node, decoded.command]
            return
        node.heard_ns = now
        if node.wire_state not in _ENGAGED:
            node.setpoint_counter = -1  # disabled, faulted or rebooted: it applies nothing of ours

    def _note_heartbeat(self, heartbeat: Heartbeat, node: _Node) -> None:
        """Count and name a restart of the actuator: its heartbeat counter begins again at 0
        (not after 255), or it reports INIT (booting) after another state. Its faults then
        read DISABLED or INIT with no fault latched: without this, nothing would say why.
        A counter that goes back otherwise is named too: two actuators set to one node id."""
        last = node.heartbeat_counter
        if last is None:
            return
        if heartbeat.counter == 0 and last != 0xFF:
            how = f"its heartbeat counter began again at 0 after {last}"
        elif heartbeat.state is WireState.INIT and node.wire_state is not WireState.INIT:
            how = f"it reports INIT, booting, after {node.wire_state.name}"
        elif 0 < (last - heartbeat.counter) & 0xFF < 0x80:  # back, not on (lost heartbeats only skip ahead)
            self._detail = (f"leg {heartbeat.node}'s heartbeat counter went back from {last} to "
                            f"{heartbeat.counter}: two actuators answer as node {heartbeat.node}? check each "
                            "actuator's node id (1–6, one each), or what replays frames on the bus")
            return
        else:
            return
        node.restarts += 1
        self._detail = (f"leg {heartbeat.node} restarted ({how}): a power or watchdog reset of the actuator; "
                        "check its supply and wiring, then reset and enable")

    def _feedback(self, node: _Node, now: int) -> ActuatorFeedback:
        return ActuatorFeedback(
            position_mm=node.position_mm,
            velocity_mm_s=node.velocity_mm_s,
            state=STATE_FROM_WIRE[node.wire_state],
            fault_bits=node.fault_bits,
            fault_names=FAULT_NAMES(node.fault_bits),
            # Not heard (inf) until a HEARTBEAT shows it speaks this protocol: frames before
            # that do not make an actuator the loop may enable (send_command refuses ENABLE).
            heartbeat_age_s=_age_s(node.heard_ns if node.protocol_version == PROTOCOL_VERSION else None, now),
            setpoint_counter=node.setpoint_counter,
            restarts=node.restarts,
        )

    def _unwrap(self, wire_counter: int, floor: int) -> int:
        """The loop counter whose low byte the actuator echoes: the latest one sent that ends
        in those 8 bits (acknowledgements lag far less than 256 cycles), or −1 if that is not
        one this link sent after ``floor`` (the actuator's echo from before its ENABLE)."""
        last, first = self._last_counter, self._first_counter
        if last is None or first is None:
            return -1
        counter = last - ((last - wire_counter) & 0xFF)
        return counter if counter >= first and counter > floor else -1


def _stray_heartbeat(message: can.Message) -> int | None:
    """The node id (0–127, none of the legs') of ``message`` if it is a HEARTBEAT of this
    protocol from an actuator with a node id no leg has; None if it is anything else."""
    node = message.arbitration_id - NodeFrameBase.HEARTBEAT
    if not 0 <= node <= 0x7F:
        return None
    try:
        heartbeat = decode(NodeFrameBase.HEARTBEAT + NODE_IDS[0], message.data)
    except FrameError:
        return None
    return node if heartbeat.protocol_version == PROTOCOL_VERSION else None


def _age_s(then_ns: int | None, now_ns: int) -> float:
    return inf if then_ns is None else (now_ns - then_ns) * 1e-9
