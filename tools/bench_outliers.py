"""Benchmark ``full``'s exclusion of gross errors: mis-sightings (issue 14's scenario) and wrong readings.

For each seed: a true platform with manufacturing errors, 20 leg-lock postures per leg
(120 rows) measured at σ 0.25 mm, then one of two scenarios:

- mis-sightings: 4 rows each with one feature point moved 5–20 mm in a random direction
  (rows 2 and 4 along the platform normal, which the distance screening cannot see);
- reading typos: 4 rows each with one sensor reading off by 5–60 mm, inside the stroke
  (rows 1 and 3 in a free leg, rows 2 and 4 in the locked one, which ``hexactl calibrate``'s
  screening would also refuse; ``full`` is given them here);
- many mis-sightings: as mis-sightings, in 10 rows (8 % of the postures);
- a decimal error: one row's feature point with one coordinate ten times too large (metres off).

In pose form the points are turned into the poses they imply, as an instrument's software
would. ``full`` identifies the parameters with the exclusion on (after) and off (before),
and ``auto`` as ``hexactl calibrate`` would; the error is the largest position error of the
paper's test motions run on the true platform with the identified parameters, beside the
clean data's.

    python tools/bench_outliers.py                  # 5 seeds, every scenario and form
    python tools/bench_outliers.py --seeds 10 --scenarios typos --forms pose
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.calibration.campaign import CampaignDesign
from hexactl.calibration.data import MeasurementData, measured_poses
from hexactl.calibration.identification import calibration_info, identify
from hexactl.calibration.parameters import calibrated_geometry
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, IdentificationStatus, Method
from hexactl.calibration.validation import summarise_validation
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.rotation import rotation_matrices
from hexactl.sim.offline_campaign import OfflineCampaign, SimulationError, run_offline_campaign, validate_geometry
from hexactl.sim.true_platform import true_geometry

NOMINAL_PATH = Path(__file__).resolve().parents[1] / "config" / "platform.toml"
MIS_SIGHTED_ROWS = 4
MANY_MIS_SIGHTED_ROWS = 10
MISTYPED_ROWS = 4
SCENARIOS = ("mis-sightings", "typos", "many-mis-sightings", "decimal")


def _rows_to_corrupt(campaign: OfflineCampaign, seed: int, rows: int
                     ) -> tuple[np.random.Generator, MeasurementData, NDArray[np.intp]]:
    """A generator seeded with ``seed``, the campaign's data and ``rows`` distinct rows of it drawn by it."""
    rng = np.random.default_rng(seed)
    return rng, campaign.data, rng.choice(len(campaign.data), size=rows, replace=False)


def mis_sight(campaign: OfflineCampaign, seed: int, rows: int = MIS_SIGHTED_ROWS) -> tuple[MeasurementData, list[tuple[int, int]]]:
    """The campaign's rows with ``rows`` feature points each moved 5–20 mm; every second one
    along the platform normal (its true z axis). Returns the data and (line, point) moved."""
    rng, data, chosen = _rows_to_corrupt(campaign, 1000 + seed, rows)
    points = np.array(data.points_mm)
    moved = []
    for number, row in enumerate(chosen):
        point = int(rng.integers(points.shape[1]))
        if number % 2:
            pose = campaign.true_poses[row]
            direction = rotation_matrices(pose[3:4], pose[4:5], pose[5:6])[0][:, 2] * rng.choice([-1.0, 1.0])
        else:
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
        points[row, point] += rng.uniform(5.0, 20.0) * direction
        moved.append((int(data.lines[row]), point + 1))
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=points), sorted(moved)


def misplace_decimal(campaign: OfflineCampaign, seed: int) -> tuple[MeasurementData, list[tuple[int, int]]]:
    """The campaign's rows with one feature point's coordinate, in one row, ten times too large
    (its decimal point slipped). Returns the data and the (line, point) changed."""
    rng, data, (row,) = _rows_to_corrupt(campaign, 3000 + seed, 1)
    points = np.array(data.points_mm)
    point, axis = int(rng.integers(points.shape[1])), int(rng.integers(3))
    points[row, point, axis] *= 10.0
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=points), [(int(data.lines[row]), point + 1)]


def mistype(campaign: OfflineCampaign, seed: int, stroke_mm: tuple[float, float],
            rows: int = MISTYPED_ROWS) -> tuple[MeasurementData, list[tuple[int, int]]]:
    """The campaign's rows with ``rows`` readings each off by 5–60 mm, staying inside
    ``stroke_mm``, alternately in a free leg and in the locked one (a free leg in a free
    posture). Returns the data and (line, leg 1–6) changed."""
    rng, data, chosen = _rows_to_corrupt(campaign, 2000 + seed, rows)
    readings = np.array(data.readings_mm)
    changed = []
    for number, row in enumerate(chosen):
        locked = int(data.locked_leg[row])
        free = [leg for leg in range(1, 7) if leg != locked]
        leg = locked if number % 2 and locked else int(rng.choice(free))
        offset = rng.uniform(5.0, 60.0) * rng.choice([-1.0, 1.0])
        if not stroke_mm[0] <= readings[row, leg - 1] + offset <= stroke_mm[1]:
            offset = -offset
        readings[row, leg - 1] += offset
        changed.append((int(data.lines[row]), leg))
    return MeasurementData(data.locked_leg, readings, data.lines, points_mm=data.points_mm), sorted(changed)


def pose_form(data: MeasurementData, nominal: Geometry) -> MeasurementData:
    """The rows with each posture's points replaced by the pose fitted to them."""
    poses = measured_poses(data, np.array(nominal.measurement.feature_points)).poses
    return MeasurementData(data.locked_leg, data.readings_mm, data.lines, poses=poses)


def position_error_mm(result: IdentificationResult, nominal: Geometry, true: Geometry) -> float:
    """The largest position error of the paper's test motions under ``result``'s parameters;
    infinite where they are so wrong that the true platform cannot run the motions, or where
    the fit left some parameter undetermined (no calibration can be written from it)."""
    if result.status is IdentificationStatus.NOT_OBSERVABLE:
        return float("inf")
    info = calibration_info(result, "bench", "", nominal.name or "")
    calibrated = calibrated_geometry(nominal, result.parameters, info)
    try:
        return summarise_validation(validate_geometry(calibrated, true)).max_position_error_mm
    except SimulationError:
        return float("inf")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--forms", nargs="+", default=["points", "pose"], choices=["points", "pose"])
    arguments = parser.parse_args()
    nominal = load_geometry(NOMINAL_PATH)
    cases = [(scenario, form) for scenario in arguments.scenarios for form in arguments.forms]
    errors: dict[tuple[str, str], dict[str, list[float]]] = {
        case: {"clean": [], "before": [], "after": [], "auto": []} for case in cases}
    recovered = {case: 0 for case in cases}
    chosen: dict[tuple[str, str], Counter[str]] = {case: Counter() for case in cases}
    full = IdentificationOptions(method=Method.FULL)
    for seed in range(arguments.seeds):
        true = true_geometry(nominal, seed=seed)
        campaign = run_offline_campaign(nominal, true, CampaignDesign(seed=seed))
        for scenario, form in cases:
            # Each excluded observation as (line, feature point or 0, leg or 0).
            if scenario == "typos":
                corrupted, changed = mistype(campaign, seed, nominal.limits.stroke)
                expected = sorted({(line, 0, leg) for line, leg in changed})
            else:
                corrupted, moved = (misplace_decimal(campaign, seed) if scenario == "decimal" else
                                    mis_sight(campaign, seed, MANY_MIS_SIGHTED_ROWS if scenario.startswith("many")
                                              else MIS_SIGHTED_ROWS))
                expected = sorted({(line, point if form == "points" else 0, 0) for line, point in moved})
            clean, bad = campaign.data, corrupted
            if form == "pose":
                clean, bad = pose_form(clean, nominal), pose_form(bad, nominal)
            runs = {"clean": identify(clean, nominal, full),
                    "before": identify(bad, nominal, replace(full, exclusion_false_alarm=0.0)),
                    "after": identify(bad, nominal, full),
                    "auto": identify(bad, nominal)}
            case = scenario, form
            for name, result in runs.items():
                errors[case][name].append(position_error_mm(result, nominal, true))
            listed = sorted({(e.line, e.point, e.leg) for e in runs["after"].excluded})
            recovered[case] += listed == expected
            chosen[case][str(runs["auto"].method)] += 1
            print(f"seed {seed} {scenario} {form}: "
                  + ", ".join(f"{name} {errors[case][name][-1]:.3f} mm" for name in runs)
                  + f"; auto chose {runs['auto'].method}; excluded {listed} (corrupted {expected})", flush=True)
    print("\n| scenario | form | clean | no exclusion (before) | exclusion (after) | auto | auto chose "
          "| exactly the corrupted observations excluded |")
    print("|---|---|---|---|---|---|---|---|")
    for (scenario, form), values in errors.items():
        cells = [f"{np.mean(values[name]):.3f} / {np.max(values[name]):.3f}" for name in ("clean", "before", "after", "auto")]
        methods = ", ".join(f"{method} {times}" for method, times in chosen[scenario, form].most_common())
        print(f"| {scenario} | {form} | {' | '.join(cells)} | {methods} | {recovered[scenario, form]} of {arguments.seeds} |")
    print("\nlargest position error of the test motions, mm: mean / worst over seeds")


if __name__ == "__main__":
    main()
