"""Six simulated actuator firmwares on one python-can bus.

:class:`ActuatorBus` delivers every frame it receives to the six
:class:`~hexactl.sim.actuator_firmware.ActuatorFirmware` and sends what they answer. It runs

* stepped by the caller with explicit times (:meth:`ActuatorBus.step`): deterministic tests on
  a ``virtual:`` bus, no thread, no wall clock;
* in a thread of the caller's process (:meth:`ActuatorBus.start` / :meth:`ActuatorBus.stop`),
  e.g. on ``virtual:NAME`` beside an in-process controller;
* in the foreground (:meth:`ActuatorBus.serve`), which ``hexactl sim-actuators`` does in its
  own process on ``socketcan:vcan0`` or a real bus.

Live runs use a fixed physics tick (1 ms by default) and handle each frame as it arrives, so a
SYNC is answered with FEEDBACK at once, not at the next tick. What the six answer to the
frames handled together goes out together, in one system call where the bus can batch frames
(a ``send_batch`` method, as :class:`~hexactl.adapters.can.socketcan_bus.LeanSocketcanBus`
has), as six nodes answering one SYNC would reach the bus at once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

import can

from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.sim.actuator_firmware import ActuatorFirmware, ActuatorParams, FaultInjection

DEFAULT_TICK_S = 0.001
_MAX_FRAMES_PER_STEP = 1000  # bounds one step's work if a sender floods the bus
_UM_PER_MM = 1000.0


def actuator_params_for(geometry: Geometry) -> ActuatorParams:
    """Actuator parameters from a geometry's limits: soft limits at the stroke, speed limit
    ``leg_velocity_mm_s``; everything else the defaults."""
    low, high = geometry.limits.stroke
    return ActuatorParams(
        soft_limits_um=(round(low * _UM_PER_MM), round(high * _UM_PER_MM)),
        max_velocity_um_s=geometry.limits.leg_velocity_mm_s * _UM_PER_MM,
    )


def zero_posture_readings_mm(geometry: Geometry) -> list[float]:
    """The sensor readings (mm) at which ``geometry`` is in its zero posture."""
    return sensor_setpoints(geometry.legs, geometry.home.in_radians())


def make_firmwares(
    positions_mm: Sequence[float], params: ActuatorParams = ActuatorParams(), *, seed: int = 0
) -> tuple[ActuatorFirmware, ...]:
    """Six firmwares at rest at ``positions_mm`` (legs 1–6), each with its own seeded
    :class:`FaultInjection` (seed ``seed * 10 + leg``) so that injected randomness repeats."""
    if len(positions_mm) != 6:
        raise ValueError(f"need 6 positions, got {len(positions_mm)}")
    return tuple(
        ActuatorFirmware(node, position * _UM_PER_MM, params, inject=FaultInjection(seed=seed * 10 + node))
        for node, position in enumerate(positions_mm, start=1)
    )


class ActuatorBus:
    """Six firmwares on ``bus`` (the runner takes ownership: :meth:`close` shuts it down).

    ``clock`` (seconds, monotonic) is used by live runs only; the firmwares' time is the
    clock's time since :meth:`start` or :meth:`serve` began.
    """

    def __init__(
        self,
        bus: can.BusABC,
        firmwares: Sequence[ActuatorFirmware],
        *,
        tick_s: float = DEFAULT_TICK_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if [firmware.node for firmware in firmwares] != [1, 2, 3, 4, 5, 6]:
            raise ValueError("need the firmwares of nodes 1..6, in order")
        if not tick_s > 0:
            raise ValueError("tick_s must be positive")
        self.bus = bus
        self.firmwares = tuple(firmwares)
        self._positions_mm = self._positions()
        self.tick_s = tick_s
        self._clock = clock
        self._lock = threading.Lock()  # one step at a time; snapshots see whole steps
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames_sent = 0
        self.send_failures = 0
        self._outbox: list[can.Message] = []  # the answers of the step under way
        self._send_batch = getattr(bus, "send_batch", None)

    # -- stepping ------------------------------------------------------------------------

    def step(self, t_s: float) -> None:
        """Handle every frame waiting on the bus as received at ``t_s``, advance the six
        firmwares to ``t_s`` and send their answers. For stepped (deterministic) runs."""
        with self._lock:
            for _ in range(_MAX_FRAMES_PER_STEP):
                message = self.bus.recv(0.0)
                if message is None:
                    break
                self._deliver(message, t_s)
            self._advance(t_s)
            self._flush()

    def actual_positions_mm(self) -> tuple[float, ...]:
        """The six drives' true (unquantised) positions, mm, as of the last completed step.
        Lock-free (one reference, replaced at the end of each step): the control loop's
        process reads it each cycle, and waiting for this thread's lock would make the loop
        wait for this thread's turn on the CPU."""
        return self._positions_mm

    def _positions(self) -> tuple[float, ...]:
        return tuple(firmware.position_um / _UM_PER_MM for firmware in self.firmwares)

    def _deliver(self, message: can.Message, t_s: float) -> None:
        if message.is_error_frame or message.is_remote_frame or message.is_extended_id:
            return
        can_id, payload = message.arbitration_id, bytes(message.data)
        for firmware in self.firmwares:
            self._send_all(firmware.receive(can_id, payload, t_s))

    def _advance(self, t_s: float) -> None:
        for firmware in self.firmwares:
            self._send_all(firmware.advance(t_s))
        self._positions_mm = self._positions()

    def _send_all(self, frames: list[tuple[int, bytes]]) -> None:
        self._outbox.extend(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False)
                            for can_id, payload in frames)  # fmt: skip

    def _flush(self) -> None:
        """Send the outbox; a frame that cannot be sent is lost, as a real node's would be
        (nobody retries), and counted."""
        outbox, self._outbox = self._outbox, []
        if self._send_batch is not None and outbox:
            try:
                self._send_batch(outbox)
            except can.CanError as error:
                sent = getattr(error, "sent", 0)
                self.frames_sent += sent
                outbox = outbox[sent + 1 :]  # the one that failed is lost; the rest go one by one
                self.send_failures += 1
            else:
                self.frames_sent += len(outbox)
                return
        for message in outbox:
            try:
                self.bus.send(message, 0.0)
            except can.CanError:
                self.send_failures += 1
            else:
                self.frames_sent += 1

    # -- live runs -----------------------------------------------------------------------

    def serve(self, duration_s: float | None = None) -> None:
        """Run in the calling thread until :meth:`stop` (or for ``duration_s`` seconds).

        Frames are handled at the time they arrived on the bus (their receive timestamp),
        not the time this thread got round to them: when the thread is held up (the GIL, the
        scheduler), the frames queued meanwhile are replayed in order at their own times
        before the firmwares advance to now. Otherwise a stalled *simulator* would look to
        the firmwares like a controller that stopped sending, and trip their watchdog.
        """
        clock = self._clock
        origin = clock()
        # Receive timestamps are wall-clock (python-can's virtual bus and SocketCAN alike).
        wall_origin = time.time() - (clock() - origin)
        end = None if duration_s is None else origin + duration_s
        next_tick = origin
        handled_s = 0.0  # simulation time of the latest frame or tick handled; never goes back
        while not self._stop.is_set():
            now = clock()
            if end is not None and now >= end:
                break
            timeout = 0.0 if now >= next_tick else next_tick - now
            message = self.bus.recv(timeout)
            with self._lock:
                now_s = clock() - origin  # after the lock: a stall may have been waiting for it
                for _ in range(_MAX_FRAMES_PER_STEP):
                    if message is None:
                        break
                    handled_s = min(max(message.timestamp - wall_origin, handled_s), now_s)
                    self._deliver(message, handled_s)
                    message = self.bus.recv(0.0)
                if now_s + origin >= next_tick:
                    handled_s = now_s
                    self._advance(now_s)
                    # Keep to the tick grid; after a stall, resume from now instead of catching up.
                    next_tick = next_tick + self.tick_s if next_tick + self.tick_s > now_s + origin else now_s + origin + self.tick_s
                self._flush()

    def start(self) -> ActuatorBus:
        """Run :meth:`serve` in a daemon thread; returns self."""
        if self._thread is not None:
            raise RuntimeError("already running")
        self._stop.clear()
        self._thread = threading.Thread(target=self.serve, name="actuator-bus", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop a live run and wait for its thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def close(self) -> None:
        """Stop and shut the bus down."""
        self.stop()
        self.bus.shutdown()

    def __enter__(self) -> ActuatorBus:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
