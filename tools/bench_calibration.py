"""Benchmark the calibration methods on seeded simulated campaigns (the paper's protocol).

For each seed: a true platform with manufacturing errors (joints σ 2 mm, zero lengths σ
3 mm), a campaign planned on the nominal geometry and measured with three feature points
at σ 0.25 mm per coordinate; each method identifies the parameters, the controller then
runs the paper's test motions (X sweep ±600 mm, Y rotation ±20°, compound) on the true
platform and the commanded and true poses are compared. The Cramér–Rao bound is the
Fisher information of the same campaign at the true parameters, propagated to the same
validation errors.

Data sets: ``leglock`` (20 leg-lock postures per leg, 120 in all), ``free`` (120 free
postures) and ``mixed`` (120 leg-lock + 60 free).

    python tools/bench_calibration.py                     # 10 seeds, leglock and free data
    python tools/bench_calibration.py --seeds 3 --datasets leglock --report /tmp/bench-report

Prints a markdown table. Error columns are means over seeds of each run's largest |error|
over all waypoints and axes (worst seed in brackets); "× paper" is the paper method's
error divided by the method's; "/ CRB" the achieved error divided by the bound's
prediction of the same statistic. The "locked legs' readings only" bound is what any
estimator that ignores the free legs' readings (leglock, paper) can at best reach.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.report.html import CalibrationReport, ValidationComparison, write_report
from hexactl.calibration.identification import calibration_info, identify
from hexactl.calibration.parameters import calibrated_geometry
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS
from hexactl.calibration.uncertainty import analyse_information, fisher_information, predict_accuracy
from hexactl.calibration.validation import ValidationSummary, summarise_validation
from hexactl.calibration.campaign import CampaignDesign
from hexactl.sim.offline_campaign import run_offline_campaign, validate_geometry
from hexactl.sim.true_platform import true_geometry

REPOSITORY = Path(__file__).resolve().parents[1]
DATASETS = {
    "leglock": dict(postures_per_leg=20, free_postures=0),
    "free": dict(postures_per_leg=0, free_postures=120),
    "mixed": dict(postures_per_leg=20, free_postures=60),
}
LEGLOCK_ONLY_METHODS = (Method.PAPER, Method.LEGLOCK)


@dataclass
class Run:
    after: ValidationSummary
    seconds: float
    status: str


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--datasets", default="leglock,free", help="comma-separated: leglock, free, mixed")
    parser.add_argument("--methods", default="paper,leglock,full,auto")
    parser.add_argument("--paper-orderings", type=int, default=200, help="random reorderings for the paper method")
    parser.add_argument("--config", default=str(REPOSITORY / "config" / "platform.toml"))
    parser.add_argument("--report", metavar="DIR", help="write the auto method's report for the first seed and data set")
    arguments = parser.parse_args()
    nominal = load_geometry(arguments.config)
    methods = [Method(name) for name in arguments.methods.split(",")]
    datasets = arguments.datasets.split(",")
    feature_points = np.array(nominal.measurement.feature_points)

    before: dict[str, list[ValidationSummary]] = {name: [] for name in datasets}
    bounds: dict[str, list] = {name: [] for name in datasets}
    locked_bounds: dict[str, list] = {name: [] for name in datasets}
    runs: dict[tuple[str, Method], list[Run]] = {(name, method): [] for name in datasets for method in methods}
    for seed in range(arguments.seeds):
        true = true_geometry(nominal, seed)
        nominal_validation = validate_geometry(nominal, true)
        for name in datasets:
            design = CampaignDesign(**DATASETS[name], seed=seed)
            campaign = run_offline_campaign(nominal, true, design)
            before[name].append(summarise_validation(nominal_validation))
            covariance, _ = analyse_information(fisher_information(
                true.legs, campaign.true_poses, feature_points, nominal.measurement.point_sigma_mm, design.sensor_sigma_mm))
            bound = predict_accuracy(true.legs, covariance, PAPER_TEST_MOTIONS, nominal.home, seed=seed)
            bounds[name].append(bound)
            if design.postures_per_leg:  # what any estimator using only the locked legs can reach
                locked = campaign.data.locked_leg[:, None] == np.arange(1, 7)[None, :]
                locked_covariance, _ = analyse_information(fisher_information(
                    true.legs, campaign.true_poses, feature_points, nominal.measurement.point_sigma_mm,
                    design.sensor_sigma_mm, used_readings=locked))
                locked_bounds[name].append(
                    predict_accuracy(true.legs, locked_covariance, PAPER_TEST_MOTIONS, nominal.home, seed=seed))
            for method in methods:
                if method in LEGLOCK_ONLY_METHODS and not design.postures_per_leg:
                    continue
                options = IdentificationOptions(method=method, paper_orderings=arguments.paper_orderings, seed=seed)
                start = time.perf_counter()
                result = identify(campaign.data, nominal, options)
                seconds = time.perf_counter() - start
                info = calibration_info(result, "bench", "", nominal.name)
                calibrated = calibrated_geometry(nominal, result.parameters, info)
                validation = validate_geometry(calibrated, true)
                runs[(name, method)].append(Run(summarise_validation(validation), seconds, result.status.name.lower()))
                if arguments.report and seed == 0 and name == datasets[0] and method is Method.AUTO:
                    page = write_report(arguments.report, CalibrationReport(
                        f"simulated campaign ({name}, seed {seed})", "bench", nominal, result, (),
                        ValidationComparison(nominal_validation, validation, bound), true), overwrite=True)
                    print(f"report: {page}\n")
    _print_table(arguments, datasets, methods, before, bounds, locked_bounds, runs)


def _print_table(arguments, datasets, methods, before, bounds, locked_bounds, runs) -> None:
    print(f"{arguments.seeds} seeds; errors: mean over seeds of the largest |error| (worst seed); "
          "position per axis in mm, orientation per Euler angle in degrees\n")
    print("| data | method | max position error | max orientation error | × paper (pos / ori) "
          "| / CRB max (pos / ori) | / CRB RMS (pos / ori) | identification time, s (mean / max) | status |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in datasets:
        position = [b.max_position_error_mm for b in before[name]]
        orientation = [b.max_orientation_error_deg for b in before[name]]
        print(f"| {name} | before (nominal) | {np.mean(position):.3f} ({np.max(position):.3f}) | "
              f"{np.mean(orientation):.4f} ({np.max(orientation):.4f}) | | | | | |")
        bound_position = np.mean([b.expected_max_position_mm for b in bounds[name]])
        bound_orientation = np.mean([b.expected_max_orientation_deg for b in bounds[name]])
        bound_rms_position = np.mean([b.rms_position_mm for b in bounds[name]])
        bound_rms_orientation = np.mean([b.rms_orientation_deg for b in bounds[name]])
        print(f"| {name} | Cramér–Rao bound | {bound_position:.3f} | {bound_orientation:.4f} | | | | | |")
        if locked_bounds[name]:
            print(f"| {name} | bound, locked legs' readings only | "
                  f"{np.mean([b.expected_max_position_mm for b in locked_bounds[name]]):.3f} | "
                  f"{np.mean([b.expected_max_orientation_deg for b in locked_bounds[name]]):.4f} | | | | | |")
        paper = runs.get((name, Method.PAPER), [])
        for method in methods:
            found = runs[(name, method)]
            if not found:
                print(f"| {name} | {method} | n/a (needs leg-lock postures) | | | | | | |")
                continue
            position = np.array([run.after.max_position_error_mm for run in found])
            orientation = np.array([run.after.max_orientation_error_deg for run in found])
            rms_position = np.mean([run.after.rms_position_error_mm for run in found])
            rms_orientation = np.mean([run.after.rms_orientation_error_deg for run in found])
            seconds = np.array([run.seconds for run in found])
            if paper:
                paper_position = np.mean([run.after.max_position_error_mm for run in paper])
                paper_orientation = np.mean([run.after.max_orientation_error_deg for run in paper])
                versus_paper = f"{paper_position / position.mean():.1f} / {paper_orientation / orientation.mean():.1f}"
            else:
                versus_paper = "n/a"
            statuses = ", ".join(sorted({run.status for run in found}))
            print(f"| {name} | {method} | {position.mean():.3f} ({position.max():.3f}) | "
                  f"{orientation.mean():.4f} ({orientation.max():.4f}) | {versus_paper} | "
                  f"{position.mean() / bound_position:.2f} / {orientation.mean() / bound_orientation:.2f} | "
                  f"{rms_position / bound_rms_position:.2f} / {rms_orientation / bound_rms_orientation:.2f} | "
                  f"{seconds.mean():.3f} / {seconds.max():.3f} | {statuses} |")


if __name__ == "__main__":
    main()
