"""``hexactl demo``: the paper's experiment end to end, on the simulator, through the real
service path.

A :class:`~hexactl.application.service.Service` (what ``hexactl serve`` runs) runs the
controller loop on an in-process CAN bus with the six simulated actuator firmwares, the
simulated platform with seeded manufacturing errors and its simulated theodolites; the
campaign of :mod:`hexactl.application.campaign` drives it through the API on the loopback
interface, like any client. So the demo is ``hexactl serve`` + ``hexactl campaign
--apply``, plus the paper's tables: Table 1 (the compound motion: command, before,
after) and the largest errors as a percentage of the stroke, beside the paper's
2.6 % → 0.35 %.

The service runs in a child process (:class:`~hexactl.application.service.ServiceProcess`),
as it would in use: with a GIL of its own (and it starts its own API process). In one process, the campaign's planning,
identification and report (numpy, matplotlib: milliseconds to seconds without letting go
of the GIL) delay the control loop, and a loop silent for 50 ms trips the simulated
actuators' watchdog.

Time is real: the actuators move at the platform's speed. To finish in under two minutes
(about 100 s on a 2-core machine) the demo measures fewer postures than the paper (:data:`DEMO_POSTURES_PER_LEG` per leg
within :data:`DEMO_ENVELOPE_FRACTION` of the pose envelope, against 20 per leg) and
drives with :data:`DEMO_MOTION` (the legs' speed limit unchanged);
``--per-leg 20 --envelope 1`` runs the paper's count.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexactl.adapters.api.client import HexactlClient
from hexactl.application.campaign.instruments import ServiceInstrument
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import CampaignOutcome, CampaignSettings, run_campaign
from hexactl.application.campaign.store import (
    CALIBRATION_FILE,
    LOCK_FILE,
    MEASUREMENTS_FILE,
    PLAN_FILE,
    REPORT_DIRECTORY,
    VALIDATION_FILE,
    ensure_unfinished,
    make_directory,
)
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.kept_calibration import DEFAULT_FILE as DEFAULT_KEPT_CALIBRATION_FILE
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.report.html import REPORT_PAGE
from hexactl.application.service import DEFAULT_FRAMES_FILE, ServiceConfig, ServiceError, ServiceProcess
from hexactl.calibration.test_motions import PAPER_MAX_STROKE_ERROR, PAPER_STROKES, PAPER_TABLE_1
from hexactl.calibration.uncertainty import pose_fit_noise_rms
from hexactl.calibration.validation import MotionResult, largest_stroke_error, summarise_validation
from hexactl.control.trajectory import MotionLimits
from hexactl.kinematics.geometry import Geometry, GeometryError
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.calibration.campaign import CampaignDesign
from hexactl.sim.true_platform import ManufacturingErrors, true_geometry

DEMO_POSTURES_PER_LEG = 3
DEMO_ENVELOPE_FRACTION = 0.6
"""The demo's campaign: 18 postures within 60 % of the pose envelope take about a minute
and still leave the test motions within about half a millimetre (seed 0: 58 s, 0.40 mm;
4 per leg: 74 s, 0.56 mm; 20 per leg within the whole envelope, the paper's count: the
whole demo 338 s, 0.34 mm). The test motions measured after calibration are mostly the
instrument's noise."""
_DEFAULT_MOTION = MotionLimits()
DEMO_MOTION = MotionLimits(
    max_velocity=tuple(4 * v for v in _DEFAULT_MOTION.max_velocity),  # type: ignore[arg-type]
    max_acceleration=tuple(4 * v for v in _DEFAULT_MOTION.max_acceleration),  # type: ignore[arg-type]
    max_jerk=tuple(8 * v for v in _DEFAULT_MOTION.max_jerk),  # type: ignore[arg-type]
)
"""Four times the controller's default velocity and acceleration limits (up to 2 m/s² ≈
0.2 g), eight times its jerk: short moves between postures are limited by these, long
ones by the legs' 400 mm/s, which stays."""

DEMO_FAULTS_IN_A_ROW = 5
"""The demo resets every latched fault and resumes, unless it is the sixth in a row with
no measurement saved between them (then it stops: the host stalls the service faster than
it can measure). The simulator shares the host with everything else, and a host that
stalls the service's process beyond the simulated actuators' watchdog (50 ms) trips them;
the service runs real-time where it may, which makes that rare. A measurement a fault
interrupted is taken again, never kept; the faults are counted at the end."""

DEMO_START_TIMEOUT_S = 300.0
"""How long the demo waits for its service (and the service's API process) to start: a few
seconds on an idle host; beside four CPU-bound processes on two cores their imports alone
took over a minute."""

DEMO_CLIENT_TIMEOUT_S = 30.0
"""How long the demo's campaign waits for each answer of its service: milliseconds on an
idle host, but its planning runs at a lower priority than everything else (nice 5), and
on a 2-core host loaded by other work an answer took more than 5 s (the clients' default)."""

RESULT_FILES = (PLAN_FILE, MEASUREMENTS_FILE, VALIDATION_FILE, CALIBRATION_FILE, LOCK_FILE)
"""What a demo leaves in its directory besides ``report/``; ``--force`` removes them."""

STROKES = np.array([stroke for _, stroke in PAPER_STROKES])
"""The paper's single-axis strokes (X/Y ±600 mm, Z ±250 mm, roll/pitch ±23°, yaw ±60°)."""


@dataclass(frozen=True, slots=True)
class DemoSettings:
    """``directory`` for the results, the ``seed`` of the manufacturing errors, the
    instrument noise and the plan; the campaign's size; ``config`` the nominal geometry
    (None: the default); how many latched faults in a row to reset and go on after
    (:data:`DEMO_FAULTS_IN_A_ROW`); ``dashboard_http``: where to serve the browser
    dashboard to watch it (None: none)."""

    directory: Path
    seed: int = 0
    postures_per_leg: int = DEMO_POSTURES_PER_LEG
    envelope_fraction: float = DEMO_ENVELOPE_FRACTION
    config: Path | None = None
    reset_faults: int = DEMO_FAULTS_IN_A_ROW
    dashboard_http: str | None = None


def clear_results(directory: Path) -> None:
    """Remove a previous demo's results from ``directory`` (nothing else in it)."""
    for name in RESULT_FILES:
        (directory / name).unlink(missing_ok=True)
    report = directory / REPORT_DIRECTORY
    if report.is_dir():
        for page in [report / REPORT_PAGE, *report.glob("*.png")]:
            page.unlink(missing_ok=True)


def run_demo(settings: DemoSettings, progress: Progress) -> CampaignOutcome:
    """Start the service on the simulator, run the campaign with ``apply`` and print the
    paper's tables. An unfinished demo in the directory is resumed.

    Raises what :func:`~hexactl.application.campaign.runner.run_campaign` raises (a
    :class:`~hexactl.application.campaign.store.DirectoryError` for a directory holding a
    finished demo, before anything starts), and
    :class:`~hexactl.application.service.ServiceError` if the service cannot start.
    """
    started = time.monotonic()
    ensure_unfinished(settings.directory)  # before anything starts
    make_directory(settings.directory)  # the service's data directory: it must exist
    try:
        nominal = load_geometry(settings.config or default_config_path())
    except GeometryError as error:
        raise ServiceError(str(error)) from None
    local = "tcp://127.0.0.1:*"  # the real API path, on ports nobody else has
    # Real-time where the process may, as hexactl serve (ServiceConfig's default).
    # The demo's service starts on the nominal geometry and without frames whatever a service
    # run here kept, and keeps the calibration it applies nowhere a later service would find it.
    kept = tempfile.TemporaryDirectory(prefix="hexactl-demo-")
    config = ServiceConfig(config_path=settings.config, api_endpoint=local, telemetry_endpoint=local,
                           data_dirs=(settings.directory,), simulator_seed=settings.seed, motion=DEMO_MOTION,
                           log_level="WARNING", dashboard_http=settings.dashboard_http,
                           frames_path=Path(kept.name) / DEFAULT_FRAMES_FILE,
                           kept_calibration_path=Path(kept.name) / DEFAULT_KEPT_CALIBRATION_FILE)
    # The simulator's truth, rebuilt here from the same seed by the same function: for the
    # report's parameter table only; the campaign never sees it.
    truth = true_geometry(nominal, settings.seed)
    _introduce(nominal, settings, progress)
    design = CampaignDesign(postures_per_leg=settings.postures_per_leg, envelope_fraction=settings.envelope_fraction,
                            seed=settings.seed)
    campaign = CampaignSettings(settings.directory, design, apply=True, true=truth, reset_faults=settings.reset_faults)
    with (kept, ServiceProcess(config, DEMO_START_TIMEOUT_S) as service,
          HexactlClient(service.api_endpoint, timeout_s=DEMO_CLIENT_TIMEOUT_S) as client):
        outcome = run_campaign(client, nominal, ServiceInstrument(client), campaign, progress)
    progress.say("")
    for line in (table_1(outcome.before, outcome.after) + stroke_table(outcome.before, outcome.after)
                 + accuracy_lines(outcome, nominal)):
        progress.say(line)
    progress.say(f"\nreport {outcome.report} (and its PNG figures), calibration "
                 f"{settings.directory / CALIBRATION_FILE}, data in {settings.directory}")
    progress.say(f"recovered from {outcome.faults_recovered} fault(s) of the simulated actuators (a measurement one "
                 "interrupted was taken again)" if outcome.faults_recovered else "no fault to recover from")
    progress.say(f"finished in {time.monotonic() - started:.0f} s")
    return outcome


def _introduce(nominal: Geometry, settings: DemoSettings, progress: Progress) -> None:
    errors, sigma_mm = ManufacturingErrors(), nominal.measurement.point_sigma_mm
    paper = "the paper: 20" if settings.postures_per_leg != 20 else "as the paper"
    progress.say(f"hexactl demo (seed {settings.seed}): the paper's experiment on the simulated platform\n"
                 f"  service:    its own process: control loop, CAN link to six simulated actuator firmwares "
                 f"on an in-process bus\n"
                 f"  platform:   {nominal.name!r} built with seeded errors (joints σ {errors.joint_sigma_mm:g} mm, "
                 f"zero lengths σ {errors.zero_length_sigma_mm:g} mm)\n"
                 f"  instrument: simulated theodolites, σ {sigma_mm:g} mm per coordinate\n"
                 f"  campaign:   {settings.postures_per_leg} leg-lock postures per leg ({paper}) within "
                 f"{100 * settings.envelope_fraction:g} % of the pose envelope")


def accuracy_lines(outcome: CampaignOutcome, nominal: Geometry) -> list[str]:
    """The test motions' error after calibration as measured, beside what the calibration's
    covariance predicts for it: RMS over every waypoint and axis. The measurement goes
    through the instrument, whose own noise is added to the prediction it is compared with."""
    measured = summarise_validation(outcome.after)
    predicted = outcome.result.predicted
    poses = absolute_from_relative(nominal.home, np.concatenate([result.commanded_relative for result in outcome.after]))
    noise_mm, noise_deg = pose_fit_noise_rms(poses, np.array(nominal.measurement.feature_points),
                                             nominal.measurement.point_sigma_mm)
    return ["",
            "Accuracy after calibration on the test motions, RMS per axis over every waypoint",
            f"  measured through the instrument        {measured.rms_position_error_mm:8.3f} mm {measured.rms_orientation_error_deg:9.4f}°",
            f"  predicted, calibration and instrument  {np.hypot(predicted.rms_position_mm, noise_mm):8.3f} mm "
            f"{np.hypot(predicted.rms_orientation_deg, noise_deg):9.4f}°",
            f"  predicted, calibration alone           {predicted.rms_position_mm:8.3f} mm "
            f"{predicted.rms_orientation_deg:9.4f}°  (the platform's own error, which the instrument's noise hides)"]


def table_1(before: Sequence[MotionResult], after: Sequence[MotionResult]) -> list[str]:
    """The paper's Table 1 for the compound motion's last waypoint: command, achieved
    before and after calibration, and the paper's own rows (its platform)."""
    b, a = _compound(before), _compound(after)
    header = f"{'':<26}" + "".join(f"{f'{axis} ({unit})':>12}" for axis, unit in zip(POSE_AXES, POSE_UNITS))

    def row(name: str, values: Sequence[float], digits: int) -> str:
        return f"{name:<26}" + "".join(f"{value:12.{digits}f}" for value in values)

    return ["Table 1: compound motion from the zero posture", header,
            row("instruction", b.commanded_relative[-1], 2),
            row("before calibration", b.achieved_relative[-1], 3),
            row("after calibration", a.achieved_relative[-1], 3),
            *(row(f"paper: {name}", values, 2) for name, values in PAPER_TABLE_1.items() if name != "instruction")]


def stroke_table(before: Sequence[MotionResult], after: Sequence[MotionResult]) -> list[str]:
    """Each motion's largest |error| as a percentage of the stroke of its axis, before and
    after, and over all three beside the paper's."""
    lines = ["", "Largest error, % of the stroke (X/Y ±600 mm, Z ±250 mm, roll/pitch ±23°, yaw ±60°)",
             f"{'':<26}{'before':<17}{'after':<17}"]

    def cell(fraction: float, axis: str) -> str:
        return f"{100 * fraction:6.3f} % {axis:<8}"

    def cells(results: Sequence[MotionResult]) -> str:
        fraction, axis = largest_stroke_error(results, STROKES)
        return cell(fraction, POSE_AXES[axis])

    for b, a in zip(before, after):
        lines.append(f"{b.motion.name:<26}{cells([b])}{cells([a])}")
    # The paper's figure is over its X sweep and Y rotation: the single-axis motions.
    swept = [(b, a) for b, a in zip(before, after) if b.motion.axis is not None]
    lines.append(f"{'X sweep and Y rotation':<26}{cells([b for b, _ in swept])}{cells([a for _, a in swept])}")
    paper_before, paper_after = PAPER_MAX_STROKE_ERROR
    lines.append(f"{'the paper (its platform)':<26}{cell(paper_before, 'roll')}{cell(paper_after, 'x')}")
    return [line.rstrip() for line in lines]


def _compound(results: Sequence[MotionResult]) -> MotionResult:
    return next(result for result in results if result.motion.axis is None)
