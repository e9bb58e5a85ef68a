"""The built-in simulator of ``hexactl serve``: six simulated actuator firmwares on a
private ``memory:`` bus, the physical platform they move (with seeded manufacturing
errors), and the instrument that measures it (the paper's theodolites).

The service's two processes each hold a part. The firmwares run in the loop's process,
on the bus its CAN link uses (a ``memory:`` bus is per process); the API's
process answers ``measure`` with a :class:`SimulatedMeasurement` of its own, whose
platform reads the firmwares' true positions from the loop's reports
(:meth:`hexactl.application.loop_link.RemoteLoop.probe`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass

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
