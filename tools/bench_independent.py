"""Calibration on campaigns hexactl did not plan: random leg-lock postures (issue 14's table).

A campaign here is made without hexactl's planner: for each leg in turn, the leg is locked
at a random reading in the middle of its stroke and random poses within a fraction of the
pose envelope are projected onto that length (``hexactl.kinematics.leg_lock``); a pose is
kept if the nominal geometry's limits allow it. The controller (the nominal geometry)
commands each kept pose: its inverse kinematics gives the free legs' readings, the locked
leg holds its own. The true platform (manufacturing errors, and per scenario sensor gains,
offset drift or mis-placed targets) goes where those readings put it; the instrument
measures its true feature points with noise σ 0.25 mm per coordinate; the sensors read with
noise σ 0.01 mm.

``hexactl calibrate``'s ``auto`` identifies the parameters; the calibrated geometry then runs
the paper's test motions on the true platform (as it is at the campaign's end). Per
scenario, over the seeds: the largest position error of the test motions (mean and worst),
the calibration's own prediction of it (``expected max``: the mean largest error over
draws from its covariance), their ratio, the Cramér–Rao bound of the model that generated
the data for the same postures (the same prediction from the inverse Fisher information
at the true parameters, gains, drift or feature points included where the scenario has
them: what no estimator can beat), which method ``auto`` chose and how often it warned.

    python tools/bench_independent.py                  # 10 seeds, every scenario
    python tools/bench_independent.py --seeds 3 --scenarios baseline gains
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.calibration.data import MeasurementData, measured_poses
from hexactl.calibration.full import identify_full
from hexactl.calibration.identification import calibration_geometry, calibration_info, identify
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.calibration.validation import summarise_validation
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.geometry import Geometry, geometry_from_mapping
from hexactl.kinematics.inverse import leg_lengths_batch, lengths_from_readings, readings_from_lengths, sensor_setpoints
from hexactl.kinematics.leg_lock import project_to_locked_leg
from hexactl.kinematics.pose import absolute_from_relative, relative_from_absolute
from hexactl.kinematics.rotation import rotation_matrices, rotation_matrix
from hexactl.kinematics.workspace import assess_poses
from hexactl.sim.offline_campaign import validate_geometry
from hexactl.sim.true_platform import ManufacturingErrors, true_geometry

NOMINAL_PATH = Path(__file__).resolve().parents[1] / "config" / "platform.toml"
POINT_SIGMA_MM = 0.25
READING_SIGMA_MM = 0.01
ENVELOPE_FRACTION = 0.5


@dataclass(frozen=True)
class Scenario:
    """How the data depart from the baseline."""

    name: str
    per_leg: int = 20
    errors: ManufacturingErrors = ManufacturingErrors()
    mis_sighted: int = 0  # rows with one feature point moved 5–20 mm
    pose_form: bool = False  # rows as the poses the points imply, as an instrument's software gives them
    target_sigma_mm: float = 0.0  # the true feature points' offset from the nominal ones, per coordinate
    target_prior: bool = False  # hexactl is told the targets' tolerance ([measurement] feature_point_sigma_mm)
    drift_sigma_mm: float = 0.0  # each sensor offset's drift over the campaign


SCENARIOS = {
    scenario.name: scenario for scenario in (
        Scenario("baseline"),
        Scenario("4x manufacturing errors", errors=ManufacturingErrors(8.0, 12.0)),
        Scenario("mis-sightings, points", mis_sighted=4),
        Scenario("mis-sightings, poses", mis_sighted=4, pose_form=True),
        Scenario("sensor gains 5e-4", errors=ManufacturingErrors(sensor_scale_sigma=5e-4)),
        Scenario("targets 0.5 mm, tolerance given", target_sigma_mm=0.5, target_prior=True),
        Scenario("targets 0.5 mm, not given", target_sigma_mm=0.5),
        Scenario("offset drift 0.5 mm", drift_sigma_mm=0.5),
        Scenario("fewer postures (30)", per_leg=5),
    )
}


@dataclass(frozen=True)
class Campaign:
    data: MeasurementData
    true_poses: np.ndarray  # (N, 6) absolute mm/rad
    at_end: Geometry  # the true platform as it is when the campaign ends
    targets: np.ndarray  # (K, 3) the true feature points, moving frame
    drift: np.ndarray  # (6,) each sensor's reading change from the first row to the last


def random_postures(nominal: Geometry, per_leg: int, rng: np.random.Generator) -> list[tuple[int, np.ndarray, float]]:
    """(leg, commanded absolute pose, locked reading) rows, ``per_leg`` for each leg."""
    low, high = np.array(nominal.limits.pose_min), np.array(nominal.limits.pose_max)
    stroke_low, stroke_high = nominal.limits.stroke
    rows = []
    for leg in range(1, 7):
        reading = rng.uniform(stroke_low + 0.3 * (stroke_high - stroke_low), stroke_high - 0.3 * (stroke_high - stroke_low))
        length = float(lengths_from_readings(nominal.legs, reading, leg - 1))
        kept = 0
        while kept < per_leg:
            relative = rng.uniform(ENVELOPE_FRACTION * low, ENVELOPE_FRACTION * high)
            projected = project_to_locked_leg(nominal.legs, absolute_from_relative(nominal.home, relative), leg, length,
                                              nominal.characteristic_length_mm)
            if not projected.ok:
                continue
            pose = np.array(projected.pose)
            if assess_poses(nominal, [relative_from_absolute(nominal.home, pose)])[0].ok:
                rows.append((leg, pose, reading))
                kept += 1
    return rows


def run_campaign(nominal: Geometry, true: Geometry, scenario: Scenario, rng: np.random.Generator) -> Campaign:
    postures = random_postures(nominal, scenario.per_leg, rng)
    count = len(postures)
    targets = np.array(nominal.measurement.feature_points) + rng.normal(0.0, scenario.target_sigma_mm, (3, 3))
    drift = rng.normal(0.0, scenario.drift_sigma_mm, 6)  # reading change from the first row to the last
    locked, readings, points, poses = [], [], [], []
    for row, (leg, command, locked_reading) in enumerate(postures):
        reading = np.array(sensor_setpoints(nominal.legs, command))
        reading[leg - 1] = locked_reading
        offset = drift * row / max(count - 1, 1)
        physical = reading - offset + rng.normal(0.0, READING_SIGMA_MM, 6)  # what the sensor reads, without its drift
        result = forward_kinematics(true.legs, lengths_from_readings(true.legs, physical).tolist(), command)
        if not result.ok:
            raise RuntimeError(f"forward kinematics on the true platform: {result.status.name}")
        pose = np.array(result.pose)
        rotation = rotation_matrix(*pose[3:])
        locked.append(leg)
        readings.append(reading)
        points.append(targets @ rotation.T + pose[:3] + rng.normal(0.0, POINT_SIGMA_MM, (3, 3)))
        poses.append(pose)
    points = np.array(points)
    for row in rng.choice(count, scenario.mis_sighted, replace=False):
        direction = rng.normal(size=3) if row % 2 else np.array([0.0, 0.0, 1.0])  # along the normal: distances unchanged
        points[row, rng.integers(3)] += rng.uniform(5.0, 20.0) * direction / np.linalg.norm(direction)
    data = MeasurementData(np.array(locked), np.array(readings), np.arange(1, count + 1), points_mm=points)
    if scenario.pose_form:
        implied = measured_poses(data, np.array(nominal.measurement.feature_points))
        data = MeasurementData(data.locked_leg, data.readings_mm, data.lines, poses=implied.poses)
    # The sensors' zero moved by the drift: at the end, reading r means length zero + (r − drift).
    end_zero = np.array(true.zero_lengths) - true.legs.sensor_gains * drift
    at_end = geometry_from_mapping({**true.model_dump(), "zero_lengths": end_zero.tolist()}, "true platform at the end")
    return Campaign(data, np.array(poses), at_end, targets, drift)


def with_target_prior(nominal: Geometry, sigma_mm: float) -> Geometry:
    measurement = {**nominal.measurement.model_dump(), "feature_point_sigma_mm": sigma_mm}
    return geometry_from_mapping({**nominal.model_dump(), "measurement": measurement}, "nominal")


def cramer_rao_mm(true: Geometry, scenario: Scenario, campaign: Campaign) -> float:
    """The expected largest test-motion error of an efficient estimator under the model
    that generated the data: the structural parameters, plus the sensor gains, the drift
    or the feature points (with their σ 0.5 mm prior) where the scenario has them; points
    σ 0.25 mm, readings σ 0.01 mm, these postures. Computed as ``full``'s own prediction
    from noise-free data at the truth: its normal matrix there is the Fisher information."""
    poses, count = campaign.true_poses, len(campaign.true_poses)
    rotations = rotation_matrices(poses[:, 3], poses[:, 4], poses[:, 5])
    points = np.einsum("nij,kj->nki", rotations, campaign.targets) + poses[:, None, :3]
    physical = readings_from_lengths(true.legs, leg_lengths_batch(true.legs, poses))
    readings = physical + np.outer(np.linspace(0.0, 1.0, count), campaign.drift)
    data = MeasurementData(campaign.data.locked_leg, readings, campaign.data.lines, points_mm=points)
    measurement = {**true.measurement.model_dump(), "feature_points": campaign.targets.tolist(),
                   "feature_point_sigma_mm": 0.5 if scenario.target_sigma_mm else 0.0}
    start = geometry_from_mapping({**true.model_dump(), "measurement": measurement}, "the truth")
    options = IdentificationOptions(method=Method.FULL, point_sigma_mm=POINT_SIGMA_MM, reading_sigma_mm=READING_SIGMA_MM,
                                    estimate_scales=bool(scenario.errors.sensor_scale_sigma),
                                    estimate_drift=bool(scenario.drift_sigma_mm), exclusion_false_alarm=0.0)
    return identify_full(data, start, options).predicted.expected_max_position_mm


def run(scenario: Scenario, seeds: int) -> dict:
    nominal = load_geometry(NOMINAL_PATH)
    controller = with_target_prior(nominal, 0.5) if scenario.target_prior else nominal
    actual, predicted, bound, methods, warned = [], [], [], [], 0
    for seed in range(seeds):
        rng = np.random.default_rng(10_000 + seed)
        true = true_geometry(nominal, 500 + seed, scenario.errors)
        campaign = run_campaign(nominal, true, scenario, rng)
        result = identify(campaign.data, controller, IdentificationOptions())
        calibrated = calibration_geometry(controller, result, calibration_info(result, "", "0" * 64, "bench"))
        actual.append(summarise_validation(validate_geometry(calibrated, campaign.at_end)).max_position_error_mm)
        predicted.append(result.predicted.expected_max_position_mm)
        bound.append(cramer_rao_mm(true, scenario, campaign))
        extras = [name for name, estimate in (("gains", result.parameters.has_scales),
                                              ("drift", result.offset_drift_mm is not None)) if estimate]
        methods.append(str(result.method) + (f"+{'+'.join(extras)}" if extras else ""))
        warned += bool(result.warnings) or not result.ok
    ratios = np.array(actual) / np.array(predicted)
    chosen = {method: methods.count(method) for method in sorted(set(methods))}
    return {"scenario": scenario.name, "mean": np.mean(actual), "worst": np.max(actual), "predicted": np.mean(predicted),
            "bound": np.mean(bound), "ratio": np.mean(ratios), "ratio_range": (np.min(ratios), np.max(ratios)),
            "chosen": ", ".join(f"{method} {count}" for method, count in chosen.items()), "warned": warned, "seeds": seeds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--scenarios", nargs="+", choices=sorted(SCENARIOS), metavar="NAME", default=list(SCENARIOS),
                        help=f"among: {', '.join(SCENARIOS)}")
    arguments = parser.parse_args()
    started = time.monotonic()
    print("| scenario | largest test-motion error, mean / worst (mm) | predicted (mm) | Cramér–Rao bound of the "
          "generating model (mm) | actual / predicted, mean (range) | auto chose | warned |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name in arguments.scenarios:
        row = run(SCENARIOS[name], arguments.seeds)
        low, high = row["ratio_range"]
        print(f"| {row['scenario']} | {row['mean']:.3f} / {row['worst']:.3f} | {row['predicted']:.3f} | "
              f"{row['bound']:.3f} | {row['ratio']:.2f} ({low:.2f}–{high:.2f}) | {row['chosen']} | "
              f"{row['warned']} of {row['seeds']} |", flush=True)
    print(f"\n{arguments.seeds} seeds per scenario, {time.monotonic() - started:.0f} s")


if __name__ == "__main__":
    main()
