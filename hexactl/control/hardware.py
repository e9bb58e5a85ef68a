"""The hardware interface between the control loop and the six actuators.

ros2_control style: the loop (the controller) talks to the actuators only through
:class:`ActuatorInterface`; the CAN adapter implements it, and so does the in-memory
simulator (:mod:`hexactl.sim.ideal_actuators`). Nothing here knows a wire format.

Units: positions are actuator *sensor* readings in mm (leg length minus the geometry's
zero length, the same scale as :func:`hexactl.kinematics.inverse.sensor_setpoints`),
velocities mm/s, times s. Legs are numbered 1–6 at this interface, as everywhere a
person or an actuator sees them.

Threading: every method is called from the control loop's thread only, except
:meth:`ActuatorInterface.send_estop`, which must be safe to call from any thread (the
controller sends an E-stop at once from the caller's thread as well as from the loop).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Flag, IntEnum, StrEnum
from math import inf
from typing import Protocol, runtime_checkable

ACTUATOR_COUNT = 6


class ActuatorCommand(StrEnum):
    """Discrete commands to one actuator or to all. E-stop is not one of them: it has its
    own method because it must bypass everything else."""

    ENABLE = "enable"  # energise the drive and follow set-points
    DISABLE = "disable"  # stop following set-points; the drive's own safe state (brake)
    CLEAR_FAULT = "clear_fault"  # leave FAULT/ESTOP for DISABLED if the cause is gone
    LOCK = "lock"  # engage the brake and hold the current length (leg-lock mode)
    UNLOCK = "unlock"  # release the brake and follow set-points again


class EstopCause(StrEnum):
    """Why the controller sends an E-stop: the actuators log it (in the frame, where the
    protocol has room), so that whoever reads their logs after a stop can tell who stopped
    them."""

    OPERATOR = "operator"  # an estop command: a person, a client or a safety PLC through the API
    SAFETY_CHAIN = "safety_chain"  # an actuator reports E-stop: its e-stop input opened
    CONTROLLER_FAULT = "controller_fault"  # the controller cannot keep control: its loop died, or another drives


class ActuatorState(IntEnum):
    """What an actuator reports it is doing."""

    DISABLED = 0
    ENABLED = 1
    LOCKED = 2
    FAULT = 3
    ESTOP = 4


class BusState(StrEnum):
    """Health of the link to the actuators, in CAN's error-state terms."""

    ACTIVE = "active"  # healthy
    WARNING = "warning"  # error counters high; still working
    PASSIVE = "passive"  # error passive; still working, degraded
    BUS_OFF = "bus_off"  # the controller left the bus: nothing is sent
    DOWN = "down"  # the interface is closed or missing


LINK_FAILED_STATES = frozenset({BusState.BUS_OFF, BusState.DOWN})
"""Bus states in which the loop treats the link as failed."""


@dataclass(frozen=True, slots=True)
class ActuatorFeedback:
    """The latest report of one actuator.

    ``position_mm``/``velocity_mm_s``: NaN until the actuator has reported them (the
    loop then knows no pose and refuses to enable). ``heartbeat_age_s``: time since the
    last frame from this actuator arrived, s (``inf`` until the actuator has shown it can
    be enabled, e.g. announced its protocol version). ``setpoint_counter``: the ``counter`` of the last
    :meth:`ActuatorInterface.send_setpoints` call whose value the actuator applied, as
    passed to that call (an implementation with a narrower wire field unwraps it), or
    −1 if none yet. ``fault_bits``: the drive's fault word, 0 when healthy;
    ``fault_names``: its set bits' names, lowest bit first (:class:`FaultNames`).
    ``restarts``: how often it started again (a power or watchdog reset) since the interface
    opened; a restarted actuator is DISABLED with no fault, so only this says why.
    """

    position_mm: float
    velocity_mm_s: float
    state: ActuatorState
    fault_bits: int
    fault_names: tuple[str, ...]
    heartbeat_age_s: float
    setpoint_counter: int
    restarts: int = 0


class FaultNames:
    """Names the bits of a fault word from the protocol's own definition of them.

    Why the feedback carries the names (:attr:`ActuatorFeedback.fault_names`) rather than
    the loop asking the interface: the bits and their meaning are the implementation's
    protocol, which the control layer does not know, and the feedback is what reaches
    every reader (supervision, the enable check on a snapshot in the API's process,
    telemetry), so the names travel with the word they describe and cannot disagree.

    ``bits``: an :class:`enum.Flag` type with one member per defined bit (the CAN link and
    the simulator pass ``firmware_proto.codec.Fault``). A bit's name is its member's name
    lower-cased (``LIMIT_SWITCH`` → ``limit_switch``): the protocol's spelling, so that
    PROTOCOL.md finds what an operator reads. A set bit the type does not define is named
    ``bit_N`` (N counted from 0), never dropped.
    """

    def __init__(self, bits: type[Flag]) -> None:
        self._by_mask = {member.value: member.name.lower() for member in bits}
        self._named: dict[int, tuple[str, ...]] = {0: ()}  # each word named once: implementations ask every read

    def __call__(self, fault_bits: int) -> tuple[str, ...]:
        """The names of the bits set in ``fault_bits``, lowest bit first; ``()`` for 0.

        :raises ValueError: if ``fault_bits`` is negative.
        """
        names = self._named.get(fault_bits)
        if names is None:
            if fault_bits < 0:
                raise ValueError(f"a fault word is not negative, got {fault_bits}")
            masks = (1 << bit for bit in range(fault_bits.bit_length()) if fault_bits >> bit & 1)
            names = self._named[fault_bits] = tuple(self._by_mask.get(mask) or f"bit_{mask.bit_length() - 1}"
                                                    for mask in masks)
        return names


def fault_text(fault_names: Sequence[str], fault_bits: int) -> str:
    """A fault word for people: its bits' names and the word in hex, ``sensor, supply
    (0x180)``; ``none`` for 0. (The CLI, which loads no control module, writes a leg's
    the same way: :func:`hexactl.adapters.cli.telemetry_text.leg_state_text`.)"""
    return f"{', '.join(fault_names)} ({fault_bits:#x})" if fault_bits else "none"


@dataclass(frozen=True, slots=True)
class FeedbackSnapshot:
    """All six actuators' reports as of one :meth:`ActuatorInterface.read_feedback` call.

    ``actuators[i]`` is leg i + 1; ``t_ns`` is the ``time.monotonic_ns()`` of the read.
    """

    actuators: tuple[ActuatorFeedback, ...]
    t_ns: int

    @property
    def positions_mm(self) -> tuple[float, ...]:
        return tuple(a.position_mm for a in self.actuators)


@dataclass(frozen=True, slots=True)
class LinkHealth:
    """``send_failures``: failed sends (set-points, commands, E-stops) since the link
    was opened; ``detail``: a human-readable note (driver error text), may be empty.

    ``other_controller_age_s``: time since the link last heard a frame that only a
    controller sends, from another sender (another controller drives the same actuators),
    s; ``inf``: none heard since the link was opened. ``other_controller_frame``: that
    frame's kind in the protocol's words, for people (``SYNC``, ``CMD_3 ENABLE``). An
    E-stop is not counted: a safety PLC or an E-stop node may send it."""

    bus_state: BusState
    send_failures: int
    detail: str = ""
    other_controller_age_s: float = inf
    other_controller_frame: str = ""


@runtime_checkable
class ActuatorInterface(Protocol):
    """The six actuators as the control loop sees them.

    Every method is non-blocking and bounded in time, and none raises: failures are
    reported through return values and :meth:`link_health`. An implementation that
    meets an unexpected error inside a method catches it, counts it as a send failure
    (or marks the bus ``DOWN``) and returns.
    """

    def send_setpoints(self, counter: int, setpoints_mm: Sequence[float]) -> bool:
        """Queue six position set-points (sensor mm, legs 1–6 in order) for sending.

        ``counter`` increases by one per call (the loop's cycle count of sends); the
        actuators report the last one applied. Returns False when the set-points could
        not be queued (counted in :attr:`LinkHealth.send_failures`).
        """
        ...

    def send_command(self, leg: int | None, command: ActuatorCommand) -> bool:
        """Send ``command`` to leg 1–6, or to all six when ``leg`` is None.

        Returns False when it could not be sent (counted as a send failure).
        """
        ...

    def send_estop(self, cause: EstopCause = EstopCause.OPERATOR) -> bool:
        """Send an emergency stop to all actuators, saying why (``cause``, for their logs).
        Safe to call from any thread.

        Returns False when it could not be sent (counted as a send failure).
        """
        ...

    def read_feedback(self) -> FeedbackSnapshot:
        """Process what has arrived since the last call and return the latest state of
        all six actuators (never waits for new frames), their fault bits named by the
        implementation's protocol (:class:`FaultNames`)."""
        ...

    def link_health(self) -> LinkHealth:
        """The link's current state; cheap enough to call every cycle."""
        ...
