"""An independent observer of the actuator bus: every set-point that reaches the bus is
inside the actuators' stroke and no faster than their velocity limit.

The controller's own guard (:mod:`hexactl.control.guard`) promises this; the monitor checks
it from the outside, the way a bus analyser would, so the safety property does not rest on
the controller's word. It shares nothing with the controller's path to the wire: frames are
decoded by cantools from ``firmware_proto/hexapod.dbc`` (``Database.decode_message``), not
by :mod:`firmware_proto.codec`, and the CRC of PROTOCOL.md section 5 is computed here again.

What is checked, per leg, on every SETPOINT frame (SETPOINT_12/34/56, SETPOINT_ALL_FD):

* **stroke**: the set-point lies in the stroke of the geometry given (the actuators' soft
  limits, whole µm as the firmware rounds them);
* **velocity**: against the leg's *reference*, the last set-point the actuator could have
  accepted, ``|Δ| ≤ leg_velocity_mm_s × d / loop_rate + 1 µm`` with ``d`` the counter
  steps between them (mod 256): the actuator's own rule (PROTOCOL.md section 4). The 1 µm
  is the wire's rounding of both values to whole µm;
* **CRC** of every frame the controller sends that carries one (SETPOINT, SYNC, CMD), and
  that those frames decode at all: an actuator would reject them, which no controller
  should make it do.

Counter gaps. A step of ``d`` counters allows ``d`` velocity steps, so cycles whose frames
never reached the bus (a failed send; the link then drops the rest of the cycle) are
covered. Deadlines the loop *skips* after an overrun do not advance the counter: the next
set-point moves at most one step in two or more periods of wall time, slower than the
limit, never faster; the monitor counts such cycles as ``late_cycles`` (a SYNC more than
1.5 periods after the previous cycle's, in one session: a controller sends no cycles while
disabled, and ENABLE starts a new stream) and keeps the longest gap. A set-point whose
counter is not *fresh* for the actuator (``d == 0``, a repeat, or ``d`` above the watchdog
window ``N`` sent with ENABLE; 100, the protocol's largest, if the monitor missed the
ENABLE) is one the actuator refuses, and by then its watchdog has stopped it with
COMM_TIMEOUT: it is counted as ``stale_setpoints``, not checked for speed, and does not
become the reference — as in the firmware.

Sessions. After ENABLE or UNLOCK the actuator's previous target is its measured position
(the bumpless start of PROTOCOL.md section 4): on a CMD frame carrying either (a new
command sequence, not a retry) the leg's reference becomes its latest FEEDBACK position,
and the first set-point after it is recorded in :attr:`BusMonitor.starts` (the jump a
controller makes when it takes over). Without any FEEDBACK seen yet the first set-point
is taken as it comes (``unreferenced_starts``).

Usage::

    with BusMonitor(service.simulator.bus_spec, geometry, 500) as monitor:
        ...                          # run the system
        monitor.catch_up()           # everything sent so far has been checked
    assert not monitor.violations

On an in-process channel (``memory:``, ``virtual:``) every bus instance hears every frame,
so a monitor opened on the same channel as a controller sees its traffic. A monitor
opened from a spec owns its bus (an unbounded receive queue on an in-process channel, so
that a slow monitor can never make the senders' frames fail); a bus passed in stays the
caller's.
"""

from __future__ import annotations

import re
import threading
import time
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from types import TracebackType

import can
from cantools.database import DecodeError

from firmware_proto import load_database
from hexactl.adapters.can.transport import IN_PROCESS_INTERFACES, open_bus, parse_bus_spec
from hexactl.kinematics.geometry import Geometry

WIRE_ROUNDING_UM = 1.0
"""Allowance on a step: each of the two set-points was rounded to the nearest µm."""

DEFAULT_WATCHDOG_CYCLES = 100
"""The freshness window assumed for a leg whose ENABLE the monitor did not see (the
protocol's largest WatchdogCycles, so no fresh set-point goes unchecked)."""

LATE_CYCLE_PERIODS = 1.5
"""A cycle whose SYNC comes this many periods or more after the previous one is late."""

MONITOR_THREAD_NAME = "bus-monitor"
"""The name of the monitor's reader thread (to find it, e.g. to give it a real-time priority)."""
_RECV_TIMEOUT_S = 0.05  # how often the idle reader looks at its stop flag
_SETPOINT_SIGNAL = re.compile(r"Setpoint([1-6])")
_COMMANDS_THAT_START = ("ENABLE", "UNLOCK")  # the actuator then follows from its measured position


def crc8_sae_j1850(data: bytes) -> int:
    """CRC-8/SAE-J1850 (PROTOCOL.md section 5): polynomial 0x1D, initial value 0xFF, final
    XOR 0xFF, no reflection; ``crc8_sae_j1850(b"123456789") == 0x4B``."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def frame_crc(can_id: int, payload: bytes) -> int:
    """The CRC a protected frame must carry in its last byte: over the 11-bit identifier as
    two bytes, low byte first, then every payload byte before the CRC byte."""
    return crc8_sae_j1850(bytes((can_id & 0xFF, can_id >> 8)) + payload[:-1])


@dataclass(frozen=True, slots=True)
class Violation:
    """A frame that breaks the safety property (or the protocol).

    :ivar what: ``outside_stroke``, ``velocity``, ``bad_crc``, ``undecodable`` or
        ``monitor_error`` (the monitor itself failed: nothing after it is checked)
    :ivar message: the details, for people (leg, value, limit, counters)
    :ivar when: the frame's receive timestamp, s (python-can's: wall clock)
    :ivar frame: (CAN id, payload)
    """

    what: str
    message: str
    when: float
    frame: tuple[int, bytes]


@dataclass(frozen=True, slots=True)
class SessionStart:
    """The first set-point a leg got after ENABLE or UNLOCK, beside the position the
    actuator reported last before it (None if it had reported none): a controller that
    takes over without a jump sends the measured position."""

    leg: int
    when: float
    measured_mm: float | None
    setpoint_mm: float

    @property
    def jump_mm(self) -> float | None:
        return None if self.measured_mm is None else abs(self.setpoint_mm - self.measured_mm)


@dataclass(frozen=True, slots=True)
class MonitorReport:
    """What the monitor saw so far.

    :ivar counts: frames by kind and the events described in the module docstring
        (``frames``, ``setpoint_frames``, ``setpoints``, ``cycles``, ``bare_syncs``,
        ``partial_cycles``, ``late_cycles``, ``stale_setpoints``, ``unreferenced_starts``,
        ``commands``, ``starts``, ``estops``, ``feedback``, ``emergencies``, ``other``)
    :ivar violations: how many :class:`Violation`
    :ivar max_step_fraction: the largest velocity step seen as a fraction of its limit
        (1.0 = at the limit; rounding allowance excluded)
    :ivar min_stroke_margin_mm: the closest any set-point came to a stroke end, mm
    :ivar max_cycle_gap_s: the longest time between consecutive cycles' SYNCs, s
    """

    counts: dict[str, int]
    violations: int
    max_step_fraction: float
    min_stroke_margin_mm: float
    max_cycle_gap_s: float


@dataclass(slots=True)
class _Leg:
    reference_um: int | None = None  # the set-point the actuator compares the next one with
    reference_counter: int | None = None  # its counter; None: the measured position after a start
    window: int = DEFAULT_WATCHDOG_CYCLES
    measured_um: int | None = None  # latest FEEDBACK position
    last_sequence: int | None = None  # latest command sequence, to tell retries from new commands
    starting: bool = False  # the next set-point is the first of a session


@dataclass(slots=True)
class _Cycle:
    counter: int | None = None
    legs: set[int] = field(default_factory=set)


class BusMonitor(can.Listener):
    """Check every frame on ``bus_or_spec`` against ``geometry``'s stroke and velocity
    limit at ``loop_rate_hz`` (the controller's loop rate: one counter step per period).

    :meth:`start` reads the bus in a thread of its own; frames can also be fed to
    :meth:`on_message_received` directly (a python-can :class:`~can.Listener`: a
    :class:`~can.Notifier` or a replayed log works too).

    :raises ValueError: if the DBC's set-point signals are not whole µm (the monitor
        would misread them)
    """

    def __init__(self, bus_or_spec: can.BusABC | str, geometry: Geometry, loop_rate_hz: float) -> None:
        if isinstance(bus_or_spec, str):
            spec = parse_bus_spec(bus_or_spec)
            options = {"rx_queue_size": 0} if spec.interface in IN_PROCESS_INTERFACES else {}
            self._bus: can.BusABC = open_bus(spec, **options)
            self._owns_bus = True
        else:
            self._bus = bus_or_spec
            self._owns_bus = False
        low_mm, high_mm = geometry.limits.stroke
        self._stroke_um = (round(low_mm * 1000.0), round(high_mm * 1000.0))  # as the firmware's soft limits
        self._step_um = geometry.limits.leg_velocity_mm_s * 1000.0 / loop_rate_hz
        self._period_s = 1.0 / loop_rate_hz
        self._database = load_database()
        self._kinds = self._frame_kinds()
        codes = {str(name): value for value, name in self._database.get_message_by_name("CMD_1")
                 .get_signal_by_name("Command").choices.items()}
        self._enable_code = codes["ENABLE"]
        self._starting_codes = {codes[name] for name in _COMMANDS_THAT_START}
        self._legs = {leg: _Leg() for leg in range(1, 7)}
        self._cycle = _Cycle()
        self._last_cycle: tuple[int, float] | None = None  # (counter, SYNC time) of the last complete cycle
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()
        self._max_step_fraction = 0.0
        self._min_margin_um = float("inf")
        self._max_gap_s = 0.0
        self._latest_s = 0.0  # timestamp of the latest frame handled
        self._idle_s = 0.0  # when the reader last found nothing to read (wall clock)
        self.violations: list[Violation] = []
        self.starts: list[SessionStart] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- lifecycle ---------------------------------------------------------------------

    def start(self) -> BusMonitor:
        """Read the bus in a daemon thread until :meth:`stop`; returns self."""
        if self._thread is not None:
            raise RuntimeError("the monitor is already running")
        self._stop.clear()
        self._thread = threading.Thread(target=self._read, name=MONITOR_THREAD_NAME, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop reading, check the frames that arrived before this call and are still
        queued, and shut the bus down if the monitor opened it. Idempotent."""
        called_s = time.time()
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            thread.join()
            for _ in range(1_000_000):  # bounded: others may still be sending
                message = self._bus.recv(0.0)
                if message is None or message.timestamp > called_s:
                    break
                self.on_message_received(message)
        if self._owns_bus:
            self._owns_bus = False
            self._bus.shutdown()

    def __enter__(self) -> BusMonitor:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None) -> None:
        self.stop()

    def catch_up(self, timeout_s: float = 10.0) -> None:
        """Wait until every frame sent before this call has been checked: the reader has
        handled a later frame, or found the bus empty after this call.

        :raises TimeoutError: if the monitor falls that far behind or stopped reading
        """
        now_s = time.time()
        deadline = time.monotonic() + timeout_s
        while self._latest_s < now_s and self._idle_s < now_s:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the bus monitor has not caught up within {timeout_s:g} s")
            time.sleep(0.005)

    def _read(self) -> None:
        recv = self._bus.recv
        while not self._stop.is_set():
            try:
                message = recv(_RECV_TIMEOUT_S)
            except Exception as error:  # noqa: BLE001 - a monitor that stops must say so
                with self._lock:
                    self._violate("monitor_error", f"receive failed, monitor stopped: {error!r}", time.time(), (0, b""))
                return
            if message is None:
                self._idle_s = time.time()
            else:
                self.on_message_received(message)

    # -- results -----------------------------------------------------------------------

    @property
    def counts(self) -> dict[str, int]:
        """A copy of the counters (see :class:`MonitorReport`)."""
        with self._lock:
            return dict(self._counts)

    def report(self) -> MonitorReport:
        """The figures so far (see :class:`MonitorReport`)."""
        with self._lock:
            return MonitorReport(dict(self._counts), len(self.violations), self._max_step_fraction,
                                 self._min_margin_um / 1000.0, self._max_gap_s)

    # -- checking ----------------------------------------------------------------------

    def on_message_received(self, msg: can.Message) -> None:
        """Check one frame (thread-safe). Never raises: a failure of the monitor itself
        is recorded as a ``monitor_error`` violation."""
        with self._lock:
            try:
                self._check(msg)
            except Exception as error:  # noqa: BLE001 - see the docstring
                self._violate("monitor_error", f"checking failed: {error!r}", msg.timestamp,
                              (msg.arbitration_id, bytes(msg.data)))
            self._latest_s = max(self._latest_s, msg.timestamp)

    def _frame_kinds(self) -> dict[int, tuple[str, object]]:
        """CAN id → (kind, argument) from the DBC: set-point frames with their legs, SYNC,
        CMD and FEEDBACK with their leg, ESTOP, EMCY."""
        kinds: dict[int, tuple[str, object]] = {}
        for message in self._database.messages:
            name = message.name
            positions = {signal.name: signal for signal in message.signals
                         if _SETPOINT_SIGNAL.fullmatch(signal.name) or signal.name == "Position"}
            for signal in positions.values():
                if (signal.unit, signal.scale, signal.offset) != ("um", 1, 0):
                    raise ValueError(f"{name}.{signal.name} is not whole µm in the DBC")
            legs = tuple(int(match[1]) for match in map(_SETPOINT_SIGNAL.fullmatch, positions) if match)
            if legs:
                kinds[message.frame_id] = ("setpoint", (legs, message.is_fd))
            elif name == "SYNC":
                kinds[message.frame_id] = ("sync", None)
            elif name == "ESTOP":
                kinds[message.frame_id] = ("estop", None)
            elif name.startswith(("CMD_ACK_", "HEARTBEAT_")):
                kinds[message.frame_id] = ("other", None)
            elif name.startswith("CMD_"):
                kinds[message.frame_id] = ("command", int(name.removeprefix("CMD_")))
            elif name.startswith("FEEDBACK_"):
                kinds[message.frame_id] = ("feedback", int(name.removeprefix("FEEDBACK_")))
            elif name.startswith("EMCY_"):
                kinds[message.frame_id] = ("emergency", None)
        return kinds

    def _check(self, msg: can.Message) -> None:
        counts = self._counts
        counts["frames"] += 1
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            counts["other"] += 1
            return
        can_id, payload = msg.arbitration_id, bytes(msg.data)
        kind, argument = self._kinds.get(can_id, ("other", None))
        if kind == "other":
            counts["other"] += 1
            return
        frame = (can_id, payload)
        protected = kind in ("setpoint", "sync", "command")
        try:
            signals = self._database.decode_message(can_id, payload, decode_choices=False)
        except (DecodeError, ValueError, KeyError) as error:
            if protected:
                self._violate("undecodable", f"0x{can_id:03X} does not decode with the DBC: {error}", msg.timestamp, frame)
            else:
                counts["other"] += 1
            return
        if protected and signals["Crc"] != (expected := frame_crc(can_id, payload)):
            self._violate("bad_crc", f"0x{can_id:03X} carries CRC 0x{signals['Crc']:02X}, expected 0x{expected:02X}",
                          msg.timestamp, frame)
            return
        if kind == "setpoint":
            legs, applies_at_once = argument
            self._setpoints(legs, signals, msg.timestamp, frame)
            if applies_at_once:  # SETPOINT_ALL_FD is its own SYNC
                self._sync(signals["Counter"], msg.timestamp)
        elif kind == "sync":
            self._sync(signals["Counter"], msg.timestamp)
        elif kind == "command":
            self._command(argument, signals)
        elif kind == "feedback":
            counts["feedback"] += 1
            self._legs[argument].measured_um = signals["Position"]
        elif kind == "estop":
            counts["estops"] += 1
        else:
            counts["emergencies"] += 1

    def _command(self, leg_number: int, signals: dict) -> None:
        self._counts["commands"] += 1
        leg = self._legs[leg_number]
        sequence = signals["Sequence"]
        if sequence == leg.last_sequence:
            return  # a retry: the actuator acknowledges it again but does not execute it again
        leg.last_sequence = sequence
        code = signals["Command"]
        if code in self._starting_codes:
            self._last_cycle = None  # the stream restarts: the time since its last cycle is no gap in it
            if code == self._enable_code:
                leg.window = signals["WatchdogCycles"]
            leg.reference_um = leg.measured_um
            leg.reference_counter = None
            leg.starting = True

    def _setpoints(self, legs: Iterable[int], signals: dict, when: float, frame: tuple[int, bytes]) -> None:
        counts = self._counts
        counts["setpoint_frames"] += 1
        counter = signals["Counter"]
        if self._cycle.counter != counter:
            self._cycle = _Cycle(counter)
        low, high = self._stroke_um
        for number in legs:
            value = signals[f"Setpoint{number}"]
            counts["setpoints"] += 1
            self._cycle.legs.add(number)
            if not low <= value <= high:
                self._violate("outside_stroke", f"leg {number}: set-point {value / 1000:.3f} mm outside the stroke "
                              f"[{low / 1000:g}, {high / 1000:g}] mm (counter {counter})", when, frame)
            else:
                self._min_margin_um = min(self._min_margin_um, value - low, high - value)
            self._step(number, value, counter, when, frame)

    def _step(self, number: int, value: int, counter: int, when: float, frame: tuple[int, bytes]) -> None:
        leg = self._legs[number]
        if leg.starting:
            leg.starting = False
            self._counts["starts"] += 1
            measured = None if leg.reference_um is None else leg.reference_um / 1000.0
            self.starts.append(SessionStart(number, when, measured, value / 1000.0))
        if leg.reference_um is None:
            self._counts["unreferenced_starts"] += 1
            leg.reference_um, leg.reference_counter = value, counter
            return
        steps = 1 if leg.reference_counter is None else (counter - leg.reference_counter) & 0xFF
        if not 1 <= steps <= leg.window:
            self._counts["stale_setpoints"] += 1  # the actuator refuses it; its watchdog has stopped it
            return
        limit = self._step_um * steps
        change = abs(value - leg.reference_um)
        self._max_step_fraction = max(self._max_step_fraction, change / limit)
        if change > limit + WIRE_ROUNDING_UM:
            previous = "the measured position" if leg.reference_counter is None else f"counter {leg.reference_counter}"
            self._violate("velocity", f"leg {number}: set-point moved {change / 1000:.3f} mm from {previous} to "
                          f"counter {counter} ({steps} cycle(s)); the limit is {limit / 1000:.3f} mm", when, frame)
        leg.reference_um, leg.reference_counter = value, counter

    def _sync(self, counter: int, when: float) -> None:
        counts = self._counts
        cycle, self._cycle = self._cycle, _Cycle()
        if cycle.counter != counter or not cycle.legs:
            counts["bare_syncs"] += 1
            return
        if len(cycle.legs) < len(self._legs):
            counts["partial_cycles"] += 1  # the missing legs miss this cycle; not a safety matter
            return
        counts["cycles"] += 1
        last = self._last_cycle
        if last is not None and (counter - last[0]) & 0xFF == 1:
            gap = when - last[1]
            self._max_gap_s = max(self._max_gap_s, gap)
            if gap >= LATE_CYCLE_PERIODS * self._period_s:
                counts["late_cycles"] += 1
        self._last_cycle = (counter, when)

    def _violate(self, what: str, message: str, when: float, frame: tuple[int, bytes]) -> None:
        self.violations.append(Violation(what, message, when, frame))
