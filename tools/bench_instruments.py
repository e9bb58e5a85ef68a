"""Calibration from each instrument's own observations: points (σ 0.25 mm per coordinate,
the paper's), two theodolites (2″ per angle) and a laser tracker (15 µm range, 1″ angles),
at the stations of docs/calibration.md's example files.

Per seed: a true platform, the planner's 20 leg-lock postures per leg, the instrument's
observations with their native noise, ``full``; the largest position error of the paper's
test motions, its prediction (expected largest error from the covariance), χ²/dof and the
identification's time.

    python tools/bench_instruments.py            # 5 seeds
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.calibration.campaign import CampaignDesign
from hexactl.calibration.data import MeasurementData
from hexactl.calibration.identification import identify
from hexactl.calibration.observations import LaserTracker, Station, Theodolites, point_covariance
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.calibration.uncertainty import DEFAULT_READING_SIGMA_MM
from hexactl.calibration.validation import summarise_validation
from hexactl.calibration.parameters import calibrated_geometry
from hexactl.calibration.identification import calibration_info
from hexactl.sim.instrument import observe
from hexactl.sim.offline_campaign import run_offline_campaign, validate_geometry
from hexactl.sim.true_platform import true_geometry

NOMINAL_PATH = Path(__file__).resolve().parents[1] / "config" / "platform.toml"
ARCSEC = np.radians(1.0 / 3600.0)
INSTRUMENTS = {
    "theodolites": Theodolites((Station((4000.0, -3000.0, 1500.0, 0.0, 0.0, 140.0)),
                                Station((4000.0, 3000.0, 1500.0, 0.0, 0.0, -140.0))), 2 * ARCSEC),
    "tracker": LaserTracker(Station((-3500.0, 500.0, 1000.0, 0.0, 0.0, 10.0)), 0.015, ARCSEC),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    seeds = parser.parse_args().seeds
    nominal = load_geometry(NOMINAL_PATH)
    rows: dict[str, list[tuple[float, float, float, float]]] = {name: [] for name in ("points", *INSTRUMENTS)}
    for seed in range(seeds):
        true = true_geometry(nominal, seed)
        campaign = run_offline_campaign(nominal, true, CampaignDesign(postures_per_leg=20, candidates=300, seed=seed,
                                                                      sensor_sigma_mm=DEFAULT_READING_SIGMA_MM))
        data = campaign.data
        forms = {"points": data}
        for name, instrument in INSTRUMENTS.items():
            points = instrument.points(observe(instrument, np.array(nominal.measurement.feature_points),
                                               campaign.true_poses, seed))
            forms[name] = MeasurementData(data.locked_leg, data.readings_mm, data.lines, points_mm=points,
                                          point_covariance_mm2=point_covariance(instrument, points))
        for name, form in forms.items():
            started = time.perf_counter()
            result = identify(form, nominal, IdentificationOptions(method=Method.FULL))
            seconds = time.perf_counter() - started
            calibrated = calibrated_geometry(nominal, result.parameters, calibration_info(result, "", "0" * 64, "bench"))
            error = summarise_validation(validate_geometry(calibrated, true)).max_position_error_mm
            rows[name].append((error, result.predicted.expected_max_position_mm, result.chi2_per_dof, seconds))
    print("| observations | largest test-motion error, mean / worst (mm) | predicted (mm) | χ²/dof | identification (s) |")
    print("| --- | --- | --- | --- | --- |")
    for name, values in rows.items():
        array = np.array(values)
        print(f"| {name} | {array[:, 0].mean():.4f} / {array[:, 0].max():.4f} | {array[:, 1].mean():.4f} | "
              f"{array[:, 2].mean():.2f} | {np.median(array[:, 3]):.2f} |")
    print(f"\n{seeds} seeds")


if __name__ == "__main__":
    main()
