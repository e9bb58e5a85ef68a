"""``hexactl calibrate``, ``plan-leglock``, ``simulate-campaign`` and ``campaign``: the
calibration workflow.

Exit status as everywhere: 0 success, 1 the answer is "no" (identification failed or
not trustworthy, no feasible plan, a campaign that could not finish or did not improve
the accuracy), 2 bad input (arguments, files, bad rows) or no answer from the service.

The calibration (numpy, scipy), the files and the report load in the functions that run
the commands, and the options whose defaults come from them are declared only for the
command that is run (:class:`~hexactl.adapters.cli.common.DeferredParser`): they must not
slow every other command's start.
"""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from math import isfinite
from pathlib import Path
from typing import TYPE_CHECKING

from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT
from hexactl.adapters.cli.common import (
    CliError,
    campaign_stopped,
    check_campaign_arguments,
    check_output,
    check_writable,
    checked_number,
    client_endpoint,
    config_input,
    connect,
    connection_parser,
    finite_float,
    load_config,
    named_path,
    non_negative_int,
    positive_int,
    whole_number,
    whole_number_in,
    write_failed,
)

if TYPE_CHECKING:
    from hexactl.adapters.api.client import HexactlClient
    from hexactl.calibration.observations import Instrument
    from hexactl.calibration.results import IdentificationResult
    from hexactl.kinematics.geometry import Geometry


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    calibrate = subparsers.add_parser(
        "calibrate",
        parents=[common],
        help="identify the structural parameters from measured postures",
        description="Identify base joints, platform joints and zero lengths from a measurement CSV and write "
        "a calibration file (the --config geometry with identified values and a [calibration] table). "
        "Exit status 1 if the identification fails or the data cannot determine the parameters.",
        epilog="See docs/calibration.md for the CSV format and the methods.",
        declare=_declare_calibrate,
    )
    calibrate.set_defaults(run=run_calibrate)

    plan = subparsers.add_parser(
        "plan-leglock",
        parents=[common],
        help="plan leg-lock postures that keep every limit and spread for observability",
        description="Plan COUNT postures with leg N locked (its length kept), inside every limit with margin, "
        "chosen D-optimally from random feasible candidates. The leg is locked at its length in the zero "
        "posture unless --length or --reading is given. --leg 0 plans free postures. Output: CSV of relative "
        "poses (mm, deg) and sensor set-points. Exit status 1 if too few candidates are feasible.",
        declare=_declare_plan,
    )
    plan.set_defaults(run=run_plan)

    simulate = subparsers.add_parser(
        "simulate-campaign",
        parents=[common],
        help="simulate a calibration campaign on a platform with random manufacturing errors",
        description="Plan leg-lock (and free) postures on the --config geometry, run them on a simulated platform "
        "with seeded manufacturing errors, measure the feature points with a simulated instrument and write "
        "the measurement CSV (and the true geometry, to validate a calibration against).",
        declare=_declare_simulate,
    )
    simulate.set_defaults(run=run_simulate)

    campaign = subparsers.add_parser(
        "campaign",
        parents=[common, connection_parser()],
        help="calibrate a running controller: drive, measure, identify, validate (leg-lock campaign)",
        description="Drive the controller behind --api through leg-lock postures for all six legs (planned on the "
        "--config geometry, which it must run), record the sensor readings and measure each posture with the "
        "instrument, saving every measurement into DIR as it goes; identify the parameters, write DIR/calibration.toml, "
        "measure the paper's test motions before and after loading it, and write the report DIR/report/. An "
        "interrupted campaign resumes when run again with the same DIR. Exit status 0 if the calibration improved "
        "the accuracy, 1 if not or if the campaign could not finish, 2 for bad input or no answer, 130 interrupted.",
        epilog="See docs/calibration.md (the campaign).",
        declare=_declare_campaign,
    )
    campaign.set_defaults(run=run_campaign_command)


def _declare_simulate(simulate: argparse.ArgumentParser) -> None:
    from hexactl.calibration.planning import DEFAULT_CANDIDATES
    from hexactl.kinematics.geometry import noise_sigma_problem

    simulate.add_argument("-o", "--output", required=True, type=named_path, metavar="DATA.csv", help="measurement file to write")
    simulate.add_argument("--true-output", type=named_path, metavar="TRUE.toml", help="also write the simulated true geometry")
    # Each plan draws DEFAULT_CANDIDATES candidates here (no --candidates): it can give no more postures.
    simulate.add_argument("--per-leg", type=whole_number_in(0, DEFAULT_CANDIDATES), default=20,
                          help=f"leg-lock postures per leg (default 20, at most {DEFAULT_CANDIDATES})")
    simulate.add_argument("--free", type=whole_number_in(0, DEFAULT_CANDIDATES), default=0,
                          help=f"free postures (default 0, at most {DEFAULT_CANDIDATES})")
    simulate.add_argument("--seed", type=non_negative_int, default=0, help="seed of errors, plans and noise (default 0)")
    simulate.add_argument("--point-sigma", type=checked_number(noise_sigma_problem), metavar="MM",
                          help="instrument noise (default: the geometry's)")
    simulate.add_argument("--pose-form", action="store_true", help="write measured poses instead of feature points")
    simulate.add_argument("--instrument", type=named_path, metavar="FILE", help="write the angles (and ranges) of the instrument this "
                          "TOML file describes, with its noise, instead of points (docs/calibration.md)")
    simulate.add_argument("--force", action="store_true", help="overwrite existing output files")


def _declare_calibrate(calibrate: argparse.ArgumentParser) -> None:
    from hexactl.calibration.results import Method, deviation_bound_problem
    from hexactl.calibration.uncertainty import DEFAULT_READING_SIGMA_MM
    from hexactl.kinematics.geometry import noise_sigma_problem

    noise = checked_number(noise_sigma_problem)

    calibrate.add_argument("data", type=named_path, metavar="DATA.csv", help="measurement file (never modified)")
    calibrate.add_argument("-o", "--output", required=True, type=named_path, metavar="CAL.toml", help="calibration file to write")
    calibrate.add_argument("--method", choices=[m.value for m in Method], default=Method.AUTO.value,
                           help="identification method (default: auto, the best for the data, explained in the output)")
    calibrate.add_argument("--report", type=named_path, metavar="DIR", help="write an HTML report with plots into DIR")
    calibrate.add_argument("--force", action="store_true", help="overwrite an existing calibration file or report")
    calibrate.add_argument("--skip-bad-rows", action="store_true",
                           help="exclude rows with problems (listed) instead of refusing the file")
    calibrate.add_argument("--scales", action="store_true", help="also identify the six sensor scale errors (full)")
    calibrate.add_argument("--instrument", type=named_path, metavar="FILE", help="the instrument (TOML: theodolites or a laser tracker, "
                           "its stations and noise) whose own angles and ranges DATA holds (docs/calibration.md)")
    calibrate.add_argument("--point-sigma", type=noise, metavar="MM",
                           help="instrument noise per coordinate, 1σ (default: the geometry's point_sigma_mm)")
    calibrate.add_argument("--reading-sigma", type=noise, default=DEFAULT_READING_SIGMA_MM, metavar="MM",
                           help=f"sensor reading noise, 1σ (default {DEFAULT_READING_SIGMA_MM} mm)")
    calibrate.add_argument("--max-deviation", type=checked_number(deviation_bound_problem), default=15.0, metavar="MM",
                           help="leglock/paper: bound on each parameter's deviation from nominal (default 15 mm)")
    calibrate.add_argument("--loss", default="linear", choices=["linear", "soft_l1", "huber", "cauchy", "arctan"],
                           help="leglock: robust loss (default linear)")
    calibrate.add_argument("--true", type=named_path, metavar="TRUE.toml",
                           help="simulation only: the true geometry, to add before/after validation to the report")


def _declare_plan(plan: argparse.ArgumentParser) -> None:
    from hexactl.calibration.planning import DEFAULT_CANDIDATES, MAX_CANDIDATES

    plan.add_argument("--leg", type=whole_number, required=True, help="leg to lock, 1-6 (0: free postures)")
    plan.add_argument("--count", type=positive_int, required=True, help="number of postures")
    lock = plan.add_mutually_exclusive_group()
    lock.add_argument("--length", type=finite_float, metavar="MM", help="locked joint-to-joint length")
    lock.add_argument("--reading", type=finite_float, metavar="MM", help="locked sensor reading")
    plan.add_argument("--candidates", type=whole_number_in(1, MAX_CANDIDATES), default=DEFAULT_CANDIDATES,
                      help=f"random candidates (default {DEFAULT_CANDIDATES}, at most {MAX_CANDIDATES})")
    plan.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    plan.add_argument("-o", "--output", type=named_path, metavar="FILE", help="write the plan here (default: standard output)")
    plan.add_argument("--force", action="store_true", help="overwrite an existing output file")


def _declare_campaign(campaign: argparse.ArgumentParser) -> None:
    from hexactl.calibration.planning import DEFAULT_CANDIDATES, MAX_CANDIDATES

    campaign.add_argument("--out", required=True, type=named_path, metavar="DIR", help="the campaign's directory (resumed if it holds one)")
    campaign.add_argument("--api", type=client_endpoint, metavar="ENDPOINT", help="the service's command endpoint (default $HEXACTL_API, "
                          f"else the client file's api, else {DEFAULT_API_ENDPOINT})")
    campaign.add_argument("--instrument", default="sim", metavar="SOURCE",
                          help="sim: the service's simulated instrument (default); csv:FILE: a real instrument's file of "
                          "feature points p1_x … (row k = the k-th measurement, waited for); prompt: typed here")
    campaign.add_argument("--per-leg", type=whole_number, default=20, metavar="N", help="leg-lock postures per leg (default 20)")
    campaign.add_argument("--candidates", type=whole_number_in(1, MAX_CANDIDATES), default=DEFAULT_CANDIDATES,
                          help=f"random candidates per plan (default {DEFAULT_CANDIDATES}, at most {MAX_CANDIDATES})")
    campaign.add_argument("--envelope", type=float, default=1.0, metavar="F",
                          help="plan within this fraction (0, 1] of the pose envelope: shorter moves, less information "
                          "(default 1)")
    campaign.add_argument("--seed", type=non_negative_int, default=0, help="planning seed (default 0)")
    campaign.add_argument("--apply", action="store_true",
                          help="keep the calibration active afterwards, if it improved the accuracy (default: roll back)")
    campaign.add_argument("--reset-faults", type=non_negative_int, default=0, metavar="N",
                          help="simulation only: reset a latched fault (not an E-stop) and go on, unless it is the "
                          "N+1-th in a row with no measurement saved between them (default 0: stop at a fault, as a "
                          "real platform needs the operator). A measurement a fault interrupted is never kept")


LARGE_CAMPAIGN_POSTURES = 2000
"""From this many postures on, ``calibrate`` says before it starts that it takes a while."""


def run_calibrate(arguments: argparse.Namespace) -> int:
    import numpy as np

    from hexactl.adapters.files.geometry_file import save_geometry
    from hexactl.adapters.files.measurements import MeasurementFileError, read_measurements
    from hexactl.adapters.report.html import REPORT_PAGE, CalibrationReport, ValidationComparison, write_report
    from hexactl.calibration.data import screen_measurements
    from hexactl.calibration.identification import blocking_problems, calibration_geometry, calibration_info, identify
    from hexactl.calibration.results import IdentificationOptions, Method
    from hexactl.kinematics.geometry import GeometryError

    check_output(arguments.output, arguments.force, arguments.data, config_input(arguments), arguments.instrument,
                 arguments.true)
    nominal = load_config(arguments)
    output = Path(arguments.output)
    if arguments.report and (Path(arguments.report) / REPORT_PAGE).exists() and not arguments.force:
        raise CliError(f"{arguments.report} already holds a report; refusing to overwrite it (use --force)")
    if arguments.report:
        if Path(arguments.report).resolve() == output.resolve():
            raise CliError(f"--report {arguments.report} is the calibration file's own path (-o): give the report a "
                           "folder of its own")
        check_writable(Path(arguments.report), folder=True)
    _note_ignored_options(arguments)
    true = _load_geometry(arguments.true) if arguments.true else None
    point_sigma = nominal.measurement.point_sigma_mm if arguments.point_sigma is None else arguments.point_sigma
    try:
        instrument = _load_instrument(arguments.instrument) if arguments.instrument else None
        measurements = read_measurements(arguments.data, len(nominal.measurement.feature_points), instrument)
    except MeasurementFileError as error:
        raise CliError(str(error)) from None
    screened = measurements.problems + screen_measurements(
        measurements.data, np.array(nominal.measurement.feature_points), point_sigma, legs=nominal.legs,
        stroke_mm=nominal.limits.stroke, zero_readings_mm=nominal.zero_readings_mm())
    problems = blocking_problems(screened, Method(arguments.method))
    for problem in screened:
        handed = "" if problem in problems else " (left to full, which tests each observation and excludes mis-sightings)"
        print(f"{arguments.data}: {problem}{handed}", file=sys.stderr)
    if any(problem.line == 0 for problem in problems):  # the whole file: no row to skip
        raise CliError(f"{arguments.data} cannot be used as it is (see above): fix the file and run again")
    if problems and not arguments.skip_bad_rows:
        raise CliError(f"{len(problems)} row problem(s) in {arguments.data} (listed above): fix them, or pass "
                       "--skip-bad-rows to exclude those rows")
    data = measurements.data.without_lines(problem.line for problem in problems)
    if problems:
        print(f"excluded {len({problem.line for problem in problems})} row(s) with problems")
    if measurements.ignored_columns:
        print(f"ignored columns: {', '.join(measurements.ignored_columns)}")
    options = IdentificationOptions(
        method=Method(arguments.method), point_sigma_mm=point_sigma, reading_sigma_mm=arguments.reading_sigma,
        estimate_scales=arguments.scales, max_joint_deviation_mm=arguments.max_deviation,
        max_zero_length_deviation_mm=arguments.max_deviation, loss=arguments.loss)
    if len(data) >= LARGE_CAMPAIGN_POSTURES:  # minutes of work with nothing printed read as a hang
        print(f"hexactl calibrate: identifying from {len(data)} postures: this takes a while (its time and memory "
              "grow with the postures; a few hundred well spread determine every parameter)", file=sys.stderr, flush=True)
    result = identify(data, nominal, options)
    _print_result(result, nominal)
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    calibrated = None
    if result.ok:
        info = calibration_info(result, created, measurements.sha256, nominal.name or str(arguments.config or ""))
        try:
            calibrated = calibration_geometry(nominal, result, info)
            save_geometry(calibrated, output, overwrite=arguments.force)
        except GeometryError as error:
            raise CliError(str(error)) from None
        except OSError as error:
            raise write_failed(output, error) from None
        kept = f", with its status ({result.status.text}) and warnings: load-calibration repeats them"
        print(f"wrote {output}{kept if result.warnings else ''}")
    else:
        print(f"no calibration written: {result.status.text}")
    if arguments.report:  # a failed identification's too: its residuals and observability say why it failed
        validation = None
        if true is not None and calibrated is not None:
            from hexactl.sim.offline_campaign import validate_geometry  # simulation only

            validation = ValidationComparison(validate_geometry(nominal, true), validate_geometry(calibrated, true))
        report = CalibrationReport(str(arguments.data), created, nominal, result, problems, validation, true)
        try:
            page = write_report(arguments.report, report, overwrite=arguments.force)
        except OSError as error:
            raise write_failed(arguments.report, error) from None
        print(f"wrote {page}")
    return 0 if result.ok else 1


def _note_ignored_options(arguments: argparse.Namespace) -> None:
    """Say which given options the chosen method does not use (they were taken silently)."""
    from hexactl.calibration.results import IdentificationOptions

    defaults = IdentificationOptions()
    for option, given, users in (
            ("--loss", arguments.loss != defaults.loss, ("leglock", "auto")),
            ("--max-deviation", arguments.max_deviation != defaults.max_joint_deviation_mm, ("leglock", "paper", "auto"))):
        if given and arguments.method not in users:
            print(f"note: {option} applies to --method {' and '.join(users)} (auto: when it takes leglock); "
                  f"--method {arguments.method} does not use it", file=sys.stderr)


def _sigma(std: float) -> str:
    """A standard deviation in the parameter table: ∞ where the data do not determine it."""
    return f"{std:.3f}" if isfinite(std) else "∞    "


def _print_result(result: IdentificationResult, nominal: Geometry) -> None:
    import numpy as np

    from hexactl.calibration.parameters import StructuralParameters

    print(f"method: {result.reason}")
    print(f"status: {result.status.text}")
    if not np.isfinite(result.residual_rms_mm):
        for warning in result.warnings:
            print(f"warning: {warning}")
        return
    o, p = result.observability, result.predicted
    print(f"postures used: {result.postures_used}, iterations: {result.iterations}")
    print(f"fit residual RMS {result.residual_rms_mm:.4f} mm (noise model expects {result.expected_rms_mm:.4f} mm), "
          f"{result.consistency}")
    print(f"observability: condition number {o.condition_number:.3g}, smallest singular value "
          f"{o.singular_values[-1]:.3g} /mm (worst combination ±{o.worst_std_mm:.3g} mm)")
    if o.full_rank:
        print(f"predicted pose uncertainty on the paper's test motions: {p.rms_position_mm:.4f} mm, "
              f"{p.rms_orientation_deg:.5f}° RMS per axis (1σ)")
    else:  # its covariance holds only what the data determine: a figure would be far too small
        print("predicted pose uncertainty on the paper's test motions: not predicted (the data do not determine "
              "every parameter)")
    deviation = result.parameters.to_vector() - StructuralParameters.from_geometry(nominal, result.parameters.has_scales).to_vector()
    std = result.std_vector
    print("deviation from nominal ± σ, mm (±∞: not determined by the data):")
    print(f"{'leg':<4} {'base joint B x, y, z':<42} {'platform joint P x, y, z':<42} {'zero length':<18}")
    for leg in range(6):
        cells = [f"{deviation[k]:+7.3f}±{_sigma(std[k])}" for k in range(7 * leg, 7 * leg + 7)]
        print(f"{leg + 1:<4} {' '.join(cells[0:3]):<42} {' '.join(cells[3:6]):<42} {cells[6]:<18}")
    if result.parameters.has_scales:
        scales = ", ".join(f"{deviation[42 + leg]:+.3f}±{_sigma(std[42 + leg])}" for leg in range(6))
        print(f"sensor scale errors, mm per m of reading: {scales}")
    from hexactl.calibration.identification import extra_estimates

    for sentence in extra_estimates(result):
        print(f"also estimated: {sentence}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    for observation in result.excluded:
        print(f"excluded as a {observation.kind}: {observation}")


def run_plan(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.files.measurements import format_plan, write_plan
    from hexactl.calibration.planning import PlanRequest, PlanStatus, plan_postures
    from hexactl.kinematics.inverse import leg_lengths, lengths_from_readings, readings_from_lengths

    check_output(arguments.output, arguments.force, config_input(arguments))
    geometry = load_config(arguments)
    if not 0 <= arguments.leg <= 6:
        raise CliError(f"--leg {arguments.leg}: a leg is 1-6 (0 for free postures)")
    length = arguments.length
    if arguments.reading is not None:
        if not arguments.leg:
            raise CliError("--reading needs a locked leg (--leg 1-6)")
        length = float(lengths_from_readings(geometry.legs, arguments.reading, arguments.leg - 1))
    if arguments.leg and length is not None:
        reading = float(readings_from_lengths(geometry.legs, length, arguments.leg - 1))
        low, high = geometry.limits.stroke
        if not low <= reading <= high:
            given = (f"--reading {arguments.reading:g}" if arguments.reading is not None
                     else f"--length {arguments.length:g} (a reading of {reading:.6g} mm)")
            raise CliError(f"{given}: leg {arguments.leg} cannot be locked there: outside its stroke "
                           f"[{low:g}, {high:g}] mm")
    plan = plan_postures(geometry, PlanRequest(arguments.leg, arguments.count, length, arguments.candidates, arguments.seed))
    if plan.status is PlanStatus.INVALID_REQUEST:
        raise CliError(plan.message)
    if not plan.ok:
        print(f"hexactl plan-leglock: {plan.message}", file=sys.stderr)
        return 1
    home_length = (leg_lengths(geometry.legs, geometry.home.in_radians())[arguments.leg - 1]
                   if arguments.leg else float("nan"))
    comments = [f"hexactl plan-leglock on {geometry.name or 'unnamed geometry'}, seed {arguments.seed}", plan.message,
                "poses relative to the zero posture (mm, deg); l*_setpoint: sensor set-points on this geometry (mm)"]
    if arguments.leg:
        comments.append(f"leg {arguments.leg} is {home_length:.3f} mm long in the zero posture")
    if arguments.output:
        try:
            write_plan(arguments.output, plan, overwrite=arguments.force, comments=comments)
        except OSError as error:
            raise write_failed(arguments.output, error) from None
        print(f"{plan.message}\nwrote {arguments.output}")
    else:
        sys.stdout.write(format_plan(plan, comments))
    return 0


def run_simulate(arguments: argparse.Namespace) -> int:
    import numpy as np

    from hexactl.adapters.files.atomic import write_atomic
    from hexactl.adapters.files.geometry_file import save_geometry
    from hexactl.adapters.files.measurements import format_observations, write_measurements
    from hexactl.calibration.data import MeasurementData, measured_poses
    from hexactl.sim.instrument import observe
    from hexactl.calibration.campaign import CampaignDesign
    from hexactl.sim.offline_campaign import SimulationError, run_offline_campaign
    from hexactl.sim.true_platform import true_geometry

    for path in (arguments.output, arguments.true_output):
        check_output(path, arguments.force, config_input(arguments), arguments.instrument)
    if arguments.true_output and Path(arguments.true_output).resolve() == Path(arguments.output).resolve():
        raise CliError(f"--true-output {arguments.true_output} is the measurement file too: name two files")
    if not arguments.per_leg and not arguments.free:
        raise CliError("--per-leg 0 and --free 0: no posture to simulate; give either at least 1")
    nominal = load_config(arguments)
    if arguments.instrument and arguments.pose_form:
        raise CliError("--instrument and --pose-form exclude each other: an instrument's own observations are of points")
    instrument = _load_instrument(arguments.instrument) if arguments.instrument else None
    true = true_geometry(nominal, arguments.seed)
    design = CampaignDesign(postures_per_leg=arguments.per_leg, free_postures=arguments.free,
                            point_sigma_mm=arguments.point_sigma, seed=arguments.seed)
    try:
        campaign = run_offline_campaign(nominal, true, design)
    except (ValueError, SimulationError) as error:
        raise CliError(str(error)) from None
    data = campaign.data
    if arguments.pose_form:
        poses = measured_poses(data, np.array(nominal.measurement.feature_points)).poses
        data = MeasurementData(data.locked_leg, data.readings_mm, data.lines, poses=poses)
    comments = [f"hexactl simulate-campaign, seed {arguments.seed}: {arguments.per_leg} leg-lock postures per leg, "
                f"{arguments.free} free", "simulated: not measured on a real platform"]
    try:
        if instrument is not None:
            observations = observe(instrument, np.array(nominal.measurement.feature_points), campaign.true_poses,
                                   arguments.seed)
            text = format_observations(data, observations, instrument, comments)
            write_atomic(arguments.output, text.encode("utf-8"), overwrite=arguments.force)
        else:
            write_measurements(arguments.output, data, overwrite=arguments.force, comments=comments)
    except OSError as error:
        raise write_failed(arguments.output, error) from None
    if arguments.true_output:
        try:
            save_geometry(true, arguments.true_output, overwrite=arguments.force)
        except OSError as error:
            raise write_failed(arguments.true_output, error) from None
    print(f"wrote {arguments.output} ({len(data)} postures)" + (f" and {arguments.true_output}" if arguments.true_output else ""))
    return 0


def run_campaign_command(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable
    from hexactl.application.campaign.driver import CampaignError
    from hexactl.application.campaign.instruments import InstrumentError, open_instrument
    from hexactl.application.campaign.progress import Progress
    from hexactl.application.campaign.runner import CampaignSettings, calibration_left_in_force, run_campaign
    from hexactl.application.campaign.store import DirectoryError
    from hexactl.calibration.campaign import CampaignDesign

    geometry = load_config(arguments)
    check_campaign_arguments(arguments)
    check_writable(arguments.out, folder=True)
    progress = Progress()
    design = CampaignDesign(postures_per_leg=arguments.per_leg, candidates=arguments.candidates,
                            envelope_fraction=arguments.envelope, seed=arguments.seed)
    settings = CampaignSettings(arguments.out, design, apply=arguments.apply, reset_faults=arguments.reset_faults)
    with connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout) as client:
        try:
            instrument = open_instrument(arguments.instrument, client, geometry, progress.say)
            outcome = run_campaign(client, geometry, instrument, settings, progress)
        except (ValueError, InstrumentError, DirectoryError) as error:
            raise CliError(str(error)) from None
        except ServiceUnavailable as error:
            progress.finish()
            print(f"hexactl campaign: {error} What was measured is saved in {arguments.out}: run the same command "
                  "again once the service answers to resume", file=sys.stderr)
            return 2
        except (CampaignError, KeyboardInterrupt) as stopped_by:
            if isinstance(stopped_by, KeyboardInterrupt):
                _stop(client)
            status = campaign_stopped("campaign", stopped_by, arguments.out, progress)
            if left := calibration_left_in_force(client, arguments.out):
                print(f"hexactl campaign: {left}", file=sys.stderr)
            return status
    return 0 if outcome.improved else 1


def _stop(client: HexactlClient) -> None:
    """Brake a platform an interrupted campaign left moving; the lock, if any, holds."""
    from hexactl.adapters.api.client import ServiceUnavailable

    try:
        client.request("stop")
    except ServiceUnavailable:
        pass  # the service is gone: nothing to brake through it


def _load_instrument(path: str) -> Instrument:
    from hexactl.adapters.files.instrument_file import InstrumentFileError, load_instrument

    try:
        return load_instrument(path)
    except InstrumentFileError as error:
        raise CliError(str(error)) from None


def _load_geometry(path: str) -> Geometry:
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.kinematics.geometry import GeometryError

    try:
        return load_geometry(path)
    except GeometryError as error:
        raise CliError(str(error)) from None
