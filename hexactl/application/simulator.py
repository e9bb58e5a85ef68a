"""The built-in simulator of ``hexactl serve``: six simulated actuator firmwares on a
private ``memory:`` bus, the physical platform they move (with seeded manufacturing
errors), and the instrument that measures it (the paper's theodolites).

The service's two processes each hold a part. The firmwares run in the loop's process,
on the bus its CAN link uses (a ``memory:`` bus is per process); the API's
process answers ``measure`` with a :class:`SimulatedMeasurement` of its own, whose
platform reads the firmwares' true positions through the instrument's own port, as a real
instrument has its own cable: an :class:`InstrumentPort` in the loop's process, asked
through an :class:`InstrumentLine` in the API's. Nothing of the simulator travels with
the loop's reports.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection

import numpy as np

from hexactl.adapters.api.commands import MeasurementError
from hexactl.adapters.can.transport import open_bus
from hexactl.kinematics.geometry import Geometry
from hexactl.sim.actuator_bus import ActuatorBus, actuator_params_for, make_firmwares, zero_posture_readings_mm
from hexactl.sim.instrument import SimulatedInstrument
from hexactl.sim.physical_platform import PhysicalPlatform, PoseUnavailable
from hexactl.sim.true_platform import true_geometry


@dataclass(frozen=True, slots=True)
class InstrumentSpec:
    """What a :class:`SimulatedMeasurement` is made of (picklable, for the API's
    process): the true geometry, the noise stream's seed, and the noise (1σ per
    coordinate, mm; None: the geometry's ``[measurement] point_sigma_mm``)."""

    truth: Geometry
    noise_seed: int
    point_sigma_mm: float | None


class SimulatedMeasurement:
    """The simulated platform, seen through the simulated instrument.
    ``actual_positions_mm``: the six drives' true positions now (sensor mm)."""

    def __init__(self, spec: InstrumentSpec, actual_positions_mm: Callable[[], Sequence[float]]) -> None:
        self.platform = PhysicalPlatform(spec.truth, actual_positions_mm)
        self.instrument = SimulatedInstrument.for_geometry(spec.truth, spec.noise_seed, spec.point_sigma_mm)

    def measure(self, guess: Sequence[float] | None = None) -> list[list[float]]:
        """The feature points of the platform's true pose now, fixed frame, mm, with the
        instrument's noise (the API's ``measure``). ``guess``: roughly where the platform
        is (absolute mm/rad), to solve its pose from.

        :raises MeasurementError: if the platform's pose cannot be solved
        """
        try:
            pose = self.platform.true_pose(guess)
        except PoseUnavailable as error:
            raise MeasurementError(f"the simulated platform has no pose: {error}") from None
        return self.instrument.measure(pose.absolute).tolist()


INSTRUMENT_TIMEOUT_S = 2.0
"""How long :class:`InstrumentLine` waits for the port's answer (it answers in
microseconds; a loaded host's scheduler may take a while to run its thread)."""

_PORT_POLL_S = 0.2  # how often the port's thread looks whether it was closed


class InstrumentPort:
    """The simulated instrument's port in the loop's process: answers each request on its
    connection with the six drives' true positions (sensor mm) from
    ``actual_positions_mm``, on a thread of its own, until closed or the other end closes.
    :attr:`line_end` is the connection to hand to the API's process
    (:class:`InstrumentLine`)."""

    def __init__(self, actual_positions_mm: Callable[[], Sequence[float]]) -> None:
        self._positions = actual_positions_mm
        self._ours, self.line_end = multiprocessing.get_context("spawn").Pipe(duplex=True)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="simulated-instrument", daemon=True)

    def start(self) -> InstrumentPort:
        self._thread.start()
        return self

    def close(self) -> None:
        self._closing.set()
        self._thread.join(2 * _PORT_POLL_S)
        self._ours.close()
        self.line_end.close()

    def _serve(self) -> None:
        try:
            while not self._closing.is_set():
                if self._ours.poll(_PORT_POLL_S):
                    number = self._ours.recv()
                    self._ours.send((number, tuple(self._positions())))
        except (EOFError, OSError):
            pass  # the API's process closed its end


class InstrumentLine:
    """The API process's end of an :class:`InstrumentPort`: calling it returns the drives'
    true positions now, sensor mm. Thread-safe.

    :raises MeasurementError: if the port does not answer within :data:`INSTRUMENT_TIMEOUT_S`
        or is closed
    """

    def __init__(self, connection: Connection, timeout_s: float = INSTRUMENT_TIMEOUT_S) -> None:
        self._connection = connection
        self._timeout_s = timeout_s
        self._lock = threading.Lock()
        self._numbers = itertools.count(1)

    def __call__(self, timeout_s: float | None = None) -> tuple[float, ...]:
        """The positions now; ``timeout_s`` overrides the line's for this request."""
        timeout_s = self._timeout_s if timeout_s is None else timeout_s
        with self._lock:
            number = next(self._numbers)
            try:
                self._connection.send(number)
                # An answer to an earlier request that timed out may come first: skip it.
                while self._connection.poll(timeout_s):
                    answered, positions = self._connection.recv()
                    if answered == number:
                        return positions
            except (EOFError, OSError) as error:
                raise MeasurementError(f"the simulated instrument's port is closed ({error!r})") from None
            raise MeasurementError(f"the simulated instrument did not answer within {timeout_s:g} s")

    def close(self) -> None:
        self._connection.close()


class Simulator:
    """Six simulated actuator firmwares on a ``memory:`` bus of this process
    (:attr:`bus_spec`; it does not copy frames, so none of its users may change one),
    driving a simulated physical platform whose geometry is ``nominal`` with the
    manufacturing errors of :func:`~hexactl.sim.true_platform.true_geometry` for ``seed``,
    and its instrument (:attr:`instrument_spec`; noise ``point_sigma_mm``)."""

    def __init__(self, nominal: Geometry, seed: int, point_sigma_mm: float | None = None) -> None:
        truth = true_geometry(nominal, seed)
        # Private to this service. memory, not virtual: python-can's virtual bus copies every
        # frame for every receiver while holding the GIL the loop needs, a large share of the
        # loop's compute per cycle.
        self.bus_spec = f"memory:hexactl-sim-{os.getpid()}-{id(self)}"
        firmwares = make_firmwares(zero_posture_readings_mm(truth), actuator_params_for(nominal), seed=seed)
        self.runner = ActuatorBus(open_bus(self.bus_spec), firmwares).start()
        """The firmwares and the thread that runs them (fault injection: ``runner.firmwares``)."""
        # The noise has its own stream: the manufacturing errors already draw from ``seed``'s.
        noise_seed = int(np.random.SeedSequence(seed).spawn(1)[0].generate_state(1)[0])
        self.instrument_spec = InstrumentSpec(truth, noise_seed, point_sigma_mm)
        self.measurement = SimulatedMeasurement(self.instrument_spec, self.runner.actual_positions_mm)
        """The platform and instrument in this process (the API's process has its own)."""

    def close(self) -> None:
        self.runner.close()
