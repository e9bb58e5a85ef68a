"""A calibration campaign without a controller: plan, drive, measure, validate, in simulation.

The steps a controller-driven campaign performs, with the platform replaced by its true
geometry (:mod:`hexactl.sim.true_platform`) and the instrument by
:class:`~hexactl.sim.instrument.SimulatedInstrument`:

1. plan leg-lock postures for each leg (and free postures) on the controller's geometry;
2. the controller commands each: free legs get the sensor set-points its inverse
   kinematics computes, the locked leg keeps its reading;
3. the platform goes where the readings put it on the TRUE geometry (forward kinematics),
   with the sensors' own noise on the actual extensions;
4. the instrument measures the feature points: one measurement row per posture.

:func:`execute_motion` runs a test motion the same way for validation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.campaign import CampaignDesign, plan_campaign
from hexactl.calibration.data import MeasurementData
from hexactl.calibration.planning import PosturePlan
from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS, TestMotion
from hexactl.calibration.validation import MotionResult
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LEG_COUNT, lengths_from_readings, sensor_setpoints_batch
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute
from hexactl.sim.instrument import SimulatedInstrument

class SimulationError(RuntimeError):
    """The simulated platform could not reach a commanded posture (forward kinematics failed)."""


@dataclass(frozen=True, slots=True, eq=False)
class OfflineCampaign:
    """The measurement rows (``data``, feature-point form) and, for checking, the postures'
    true absolute poses ``true_poses`` (N, 6) mm/rad and the plans that were executed."""

    data: MeasurementData
    true_poses: NDArray[np.float64]
    plans: tuple[PosturePlan, ...]


def execute_plans(controller: Geometry, true: Geometry, plans: Sequence[PosturePlan],
                  instrument: SimulatedInstrument, sensor_sigma_mm: float, seed: int) -> OfflineCampaign:
    """Drive the true platform through ``plans`` under ``controller`` and measure every posture.

    Rows are numbered 1..N in ``lines``. Raises :class:`SimulationError` if forward
    kinematics on the true geometry fails for a posture.
    """
    rng = np.random.default_rng(seed)
    locked, readings, points, true_poses = [], [], [], []
    for plan in plans:
        commanded = absolute_from_relative(controller.home, plan.poses_relative)
        setpoints = sensor_setpoints_batch(controller.legs, commanded)
        if plan.leg:
            setpoints[:, plan.leg - 1] = plan.locked_reading_mm  # the locked leg holds its reading
        for command, reading in zip(commanded, setpoints):
            actual = lengths_from_readings(true.legs, reading + rng.normal(0.0, sensor_sigma_mm, LEG_COUNT))
            result = forward_kinematics(true.legs, actual, command)
            if not result.ok:
                raise SimulationError(f"forward kinematics on the true geometry: {result.status.name}")
            locked.append(plan.leg)
            readings.append(reading)
            points.append(instrument.measure(result.pose))
            true_poses.append(result.pose)
    count = len(locked)
    data = MeasurementData(np.array(locked), np.array(readings).reshape(count, LEG_COUNT),
                           np.arange(1, count + 1), points_mm=np.array(points))
    return OfflineCampaign(data, np.array(true_poses).reshape(count, 6), tuple(plans))


def run_offline_campaign(controller: Geometry, true: Geometry, design: CampaignDesign) -> OfflineCampaign:
    """Plan on ``controller`` and execute on ``true``: the whole simulated data collection."""
    plans = plan_campaign(controller, design)
    instrument = SimulatedInstrument.for_geometry(controller, seed=design.seed, point_sigma_mm=design.point_sigma_mm)
    # The sensor noise gets its own stream, independent of the instrument's.
    sensor_seed = int(np.random.SeedSequence(design.seed).spawn(1)[0].generate_state(1)[0])
    return execute_plans(controller, true, plans, instrument, design.sensor_sigma_mm, seed=sensor_seed)


def execute_motion(controller: Geometry, true: Geometry, motion: TestMotion) -> MotionResult:
    """Where the true platform goes when ``controller`` commands ``motion``'s waypoints.

    Commanded pose → inverse kinematics on the controller's geometry → sensor readings →
    forward kinematics on the true geometry (noise-free: validation measures the
    geometry, not the sensors). Raises :class:`SimulationError` on an FK failure.
    """
    commanded = absolute_from_relative(controller.home, np.array(motion.waypoints))
    readings = sensor_setpoints_batch(controller.legs, commanded)
    achieved = []
    for command, reading in zip(commanded, readings):
        result = forward_kinematics(true.legs, lengths_from_readings(true.legs, reading), command)
        if not result.ok:
            raise SimulationError(f"{motion.name}: forward kinematics on the true geometry: {result.status.name}")
        achieved.append(relative_from_absolute(controller.home, result.pose))
    return MotionResult(motion, np.array(achieved))


def validate_geometry(controller: Geometry, true: Geometry,
                      motions: Sequence[TestMotion] = PAPER_TEST_MOTIONS) -> tuple[MotionResult, ...]:
    """Every test motion under ``controller`` on the true platform (paper, section 4)."""
    return tuple(execute_motion(controller, true, motion) for motion in motions)
