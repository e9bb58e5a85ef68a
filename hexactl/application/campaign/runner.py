"""The calibration campaign on a running controller (``hexactl campaign``).

The steps of :mod:`hexactl.sim.offline_campaign`, with the controller and an instrument
doing the driving and measuring:

1. plan leg-lock postures for every leg on the controller's geometry (or resume a saved
   plan: :mod:`.store`);
2. measure the paper's test motions before calibration, waypoint by waypoint;
3. for each leg: move to the zero posture, lock the leg there, visit its postures
   (straight, or along :func:`~hexactl.calibration.campaign.locked_path` where the
   controller refuses the straight move), and at each one, once the
   platform has settled, record the six sensor readings and measure the feature points;
4. identify the parameters from the saved measurement file and write the calibration;
5. load it into the running controller and measure the test motions again;
6. keep it (``apply``, and only if the accuracy improved) or roll back; write the report.

Every measurement is saved before the next move, so an interrupted campaign (Ctrl-C, a
fault, a crash) resumes where it stopped when run again on the same directory. Nothing is
measured across a fault: a measurement is kept only if, once taken, the controller is
still enabled with no fault latched and the platform still holds where it settled
(:meth:`~.driver.PlatformDriver.confirm_still`); else the posture or waypoint is measured
again when the campaign resumes.

With ``reset_faults`` (the simulator: a loaded host can stall its actuators past their
watchdog) a latched FAULT is reset and the campaign resumes at once, as often as it
keeps measuring: it stops after ``reset_faults`` faults in a row with no measurement
saved between them. The run counts and reports the faults it recovered from.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from hexactl.adapters.api.client import CommandError, HexactlClient, ServiceUnavailable
from hexactl.application.campaign.driver import (
    ZERO_POSE,
    CampaignError,
    ControllerFault,
    PlatformDriver,
    Record,
)
from hexactl.application.campaign.instruments import Instrument
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.store import (
    CALIBRATION_FILE,
    MEASUREMENTS_FILE,
    PLAN_FILE,
    REPORT_DIRECTORY,
    VALIDATION_FILE,
    VALIDATION_STEPS,
    CampaignStore,
    saving,
)
from hexactl.adapters.files.geometry_file import (
    geometry_id,
    geometry_to_toml,
    load_geometry,
    parse_geometry,
    save_geometry,
)
from hexactl.adapters.files.measurements import MeasurementFileError
from hexactl.adapters.report.html import (
    CalibrationReport,
    ValidationComparison,
    write_report,
)
from hexactl.calibration.campaign import CampaignDesign, improved, locked_path
from hexactl.calibration.data import screen_measurements
from hexactl.calibration.identification import (
    blocking_problems,
    calibration_geometry,
    calibration_info,
    extra_estimates,
    identify,
)
from hexactl.calibration.parameters import StructuralParameters, parameter_names
from hexactl.calibration.results import IdentificationOptions, IdentificationResult
from hexactl.calibration.validation import MotionResult, summarise_validation
from hexactl.kinematics.one_line import as_one_line
from hexactl.kinematics.geometry import Geometry, GeometryError
from hexactl.kinematics.inverse import lengths_from_readings


@dataclass(frozen=True, slots=True)
class CampaignSettings:
    """How to run a campaign: its ``directory``, the plan's ``design`` (postures per leg,
    candidates, seed), whether to ``apply`` the calibration (kept only if it improved the
    accuracy), the identification ``options``; in simulation the ``true`` geometry (the
    report then compares the identified parameters with it) and ``reset_faults``: how
    many latched FAULTs (never an E-stop) in a row, with no measurement saved between
    them, are reset and the campaign resumed after (a simulator sharing a loaded host
    trips its actuators' watchdog when the host stalls the process; on a real platform a
    fault needs the operator: keep 0)."""

    directory: Path
    design: CampaignDesign = CampaignDesign()
    apply: bool = False
    options: IdentificationOptions = IdentificationOptions()
    true: Geometry | None = None
    reset_faults: int = 0


@dataclass(frozen=True, slots=True, eq=False)
class CampaignOutcome:
    """A finished campaign: the identification ``result``, the ``calibration`` written,
    the test motions ``before`` and ``after`` (relative mm/deg), whether the calibration
    ``improved`` the largest errors and whether it stays ``applied``; the report page;
    how many latched faults this run reset and resumed after (``faults_recovered``)."""

    result: IdentificationResult
    calibration: Geometry
    before: tuple[MotionResult, ...]
    after: tuple[MotionResult, ...]
    improved: bool
    applied: bool
    report: Path
    faults_recovered: int = 0


def run_campaign(client: HexactlClient, geometry: Geometry, instrument: Instrument, settings: CampaignSettings,
                 progress: Progress) -> CampaignOutcome:
    """Run (or resume) the campaign in ``settings.directory`` on the controller behind
    ``client``, whose active geometry must be ``geometry`` (the plan is made on it).

    Raises :class:`CampaignError` when it cannot go on (a fault, a refusal, bad data, a
    failed identification; the message says what to do), and
    :class:`~hexactl.application.campaign.instruments.InstrumentError`. What was measured
    stays saved either way.
    """
    driver = PlatformDriver(client)
    progress.forward_to(driver.tell)  # displays of the service (the dashboard) follow the campaign
    try:
        if not (settings.directory / PLAN_FILE).exists():  # nothing planned or written for a controller on another geometry
            driver.require_calibration(geometry_id(geometry), _planned(geometry),
                                       "start it on that geometry, or give the geometry it runs (--config)")
        with CampaignStore.open(settings.directory, geometry, settings.design) as store:
            return _run(driver, store, instrument, settings, progress)
    finally:
        progress.forward_to(None)


def _run(driver: PlatformDriver, store: CampaignStore, instrument: Instrument, settings: CampaignSettings,
         progress: Progress) -> CampaignOutcome:
    """The campaign from wherever ``store`` says it stands."""
    geometry = store.geometry
    _announce(store, instrument, progress)
    if store.postures_measured < len(store.postures):
        # Measurements are taken in one order; the postures the file lost are measured again,
        # and the calibration identified from them will not be the one those waypoints checked.
        _discard_after(store, None, f"before every posture in {MEASUREMENTS_FILE} was measured", progress)
    step = _Resetting(driver, settings.reset_faults, lambda: store.measurements_taken, progress)
    planned_id = geometry_id(geometry)

    def measure_on_the_planned_geometry() -> None:
        driver.prepare()
        if store.validation_steps_left("before") or store.postures_measured < len(store.postures):
            driver.require_calibration(planned_id, _planned(geometry), _MAKE_PLANNED_ACTIVE)
        _validate(driver, store, instrument, "before", planned_id, progress)
        _measure_postures(driver, store, instrument, progress)

    step(measure_on_the_planned_geometry)
    result, calibrated, text = _identify(store, settings.options, progress)
    calibrated_id = geometry_id(parse_geometry(text, CALIBRATION_FILE))

    step(lambda: _measure_after(driver, store, instrument, calibrated_id, text, progress))
    before, after = store.validation_results("before"), store.validation_results("after")
    better = improved(summarise_validation(before), summarise_validation(after))
    _show(before, after, better, progress)
    progress.report(campaign_report(result, calibrated_id, before, after, better))
    step(lambda: _conclude(driver, store, better, settings.apply, progress))
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    with saving(store.path(REPORT_DIRECTORY)):
        report = write_report(store.path(REPORT_DIRECTORY),
                              CalibrationReport(str(store.path(MEASUREMENTS_FILE)), created, geometry, result, (),
                                                ValidationComparison(before, after, result.predicted), settings.true),
                              overwrite=True)
    progress.say(f"wrote {report}")
    if step.resets:
        progress.say(f"recovered from {step.resets} fault(s): each posture or waypoint one interrupted was measured "
                     "again")
    return CampaignOutcome(result, calibrated, before, after, better, settings.apply and better, report, step.resets)


def _measure_after(driver: PlatformDriver, store: CampaignStore, instrument: Instrument, calibrated_id: str,
                   text: str, progress: Progress) -> None:
    """Load the calibration ``calibrated_id`` (``text``: its file) unless the controller
    runs it, and measure the test motions after calibration with it."""
    driver.prepare()
    if driver.status()["calibration_id"] != calibrated_id:
        driver.require_calibration(geometry_id(store.geometry), _planned(store.geometry), _MAKE_PLANNED_ACTIVE)
        progress.say("loading the calibration into the controller")
        driver.load_calibration(text, as_one_line(f"hexactl campaign: {store.path(CALIBRATION_FILE)}"))
    # The verdict must judge one calibration: waypoints a stopped run measured with another
    # (identified from other data since) are measured again.
    _discard_after(store, calibrated_id, f"not with {calibrated_id}, the calibration they are to check", progress)
    _validate(driver, store, instrument, "after", calibrated_id, progress)
    _to_zero(driver, "at the end of the test motions after calibration")


class _Resetting:
    """Runs a step of the campaign; when the controller latches a fault (not an E-stop),
    resets it and runs the step again, which resumes from what is saved; ``in_a_row``
    faults with no measurement saved between them (``measured``: how many are) end the
    campaign. ``resets``: how many it has reset."""

    def __init__(self, driver: PlatformDriver, in_a_row: int, measured: Callable[[], int], progress: Progress) -> None:
        self.driver, self.in_a_row, self.measured, self.progress = driver, in_a_row, measured, progress
        self.resets = 0
        self._streak = 0
        self._measured_at_fault = -1

    def __call__(self, step: Callable[[], None]) -> None:
        while True:
            try:
                return step()
            except ControllerFault as fault:
                if not fault.resettable or not self.in_a_row:
                    raise
                measured = self.measured()
                self._streak = self._streak + 1 if measured == self._measured_at_fault else 1
                self._measured_at_fault = measured
                if self._streak > self.in_a_row:
                    raise CampaignError(
                        f"{fault.summary}: {self._streak} faults in a row with no measurement saved between them "
                        f"({self.resets} recovered in all): the host stalls the service faster than the campaign "
                        "can measure. Stop other work on the host (or run as root, for real-time scheduling), "
                        "reset the controller, and run the same command again to resume") from None
                self.resets += 1
                self.progress.finish()
                self.progress.say(f"{fault.summary}; resetting it and resuming (fault {self.resets}; {self._streak} "
                                  f"in a row of at most {self.in_a_row} without a new measurement)")
                self.driver.reset()


def calibration_left_in_force(client: HexactlClient, directory: Path) -> str | None:
    """What to tell the operator of a campaign in ``directory`` that stopped, if the
    controller behind ``client`` runs the campaign's calibration (loaded for the test
    motions after calibration): it stays in force, and the service keeps it for its next
    start, until the campaign resumes and concludes or someone else swaps it. None if it
    does not (or cannot be asked)."""
    path = directory / CALIBRATION_FILE
    try:
        calibration_id = geometry_id(load_geometry(path))
        active = client.call("status")["status"]["calibration_id"]
    except (GeometryError, CommandError, ServiceUnavailable):  # none written yet, or no answer: nothing to tell
        return None
    if active != calibration_id:
        return None
    return (f"the controller still runs the campaign's calibration {calibration_id} ({path}), loaded for the test "
            "motions after calibration, and keeps it for its next start: running the same command again resumes "
            "and, at the end, rolls it back unless --apply keeps it; to go back now: hexactl rollback-calibration "
            "(after a restart of the service: hexactl load-calibration of the geometry the campaign was planned on)")


_MAKE_PLANNED_ACTIVE = ("make it active again (hexactl load-calibration of the geometry file the campaign was "
                        "planned with), then run the same command again to resume; a "
                        "campaign is resumed on the geometry it was planned on only (on the one the controller runs, "
                        "start another: --config that geometry and another --out)")


def _planned(geometry: Geometry) -> str:
    return f"the geometry the campaign is planned on ({geometry.name!r})"


def _announce(store: CampaignStore, instrument: Instrument, progress: Progress) -> None:
    design = store.design
    what = (f"{len(store.postures)} leg-lock postures ({design.postures_per_leg} per leg, seed {design.seed}) "
            f"planned on {store.geometry.name!r}")
    if store.measurements_taken:
        progress.say(f"resuming the campaign in {store.directory}: {what}; {store.postures_measured} postures and "
                     f"{store.measurements_taken - store.postures_measured} test-motion waypoints already measured")
    else:
        progress.say(f"campaign in {store.directory}: {what}")
    progress.say(f"measuring with {instrument.description}")


def _discard_after(store: CampaignStore, keep: str | None, why: str, progress: Progress) -> None:
    """Forget the saved waypoints after calibration not measured with ``keep`` (None:
    all), saying so: they are measured again."""
    stale = store.discard_after(keep)
    if stale:
        with_ = ", ".join(sorted({f"calibration {calibration_id}" if calibration_id else
                                  "no calibration recorded (a file of an older hexactl)" for calibration_id in stale}))
        progress.say(f"{len(stale)} test-motion waypoint(s) after calibration in {store.path(VALIDATION_FILE)} were "
                     f"measured with {with_}, {why}: measuring them again")


def _to_zero(driver: PlatformDriver, purpose: str) -> None:
    """Move to the zero posture (``purpose`` says why, for the message);
    :class:`CampaignError` if the controller refuses it."""
    try:
        driver.move(ZERO_POSE)
    except CommandError as error:
        raise CampaignError(f"the controller refused the move to the zero posture {purpose}: {error}. The campaign "
                            "needs the zero posture inside the controller's limits (the operator's soft limits among "
                            "them): widen them to include it, then run the same command again to resume") from None


def _validate(driver: PlatformDriver, store: CampaignStore, instrument: Instrument, phase: str, calibration_id: str,
              progress: Progress) -> None:
    """Measure the rest of ``phase``'s test-motion waypoints, each with calibration
    ``calibration_id`` active (another client may load or roll back one meanwhile)."""
    steps = store.validation_steps_left(phase)
    if steps:
        total = len(VALIDATION_STEPS[phase])
        progress.start(f"test motions {phase} calibration", total, total - len(steps))
        for step in steps:
            try:
                settled = driver.move(step.pose)
            except CommandError as error:
                raise CampaignError(f"the controller refused the test-motion move to {list(step.pose)}: {error}") from None
            label = f"{step.motion.name} {step.waypoint}/{len(step.motion.waypoints)}"
            if settled["calibration_id"] != calibration_id:
                # Named by its file: a rollback goes back one load, which after a rollback is another calibration.
                again = (f"hexactl load-calibration {store.directory.resolve() / CALIBRATION_FILE}" if phase == "after"
                         else "hexactl load-calibration of the geometry file the campaign was planned with")
                raise CampaignError(f"the controller runs calibration {settled['calibration_id']}, not {calibration_id}, "
                                    f"which the test motions {phase} calibration are measured with: another client "
                                    "loaded or rolled back a calibration meanwhile. Nothing was measured at "
                                    f"{label}; make {calibration_id} active again ({again}), then run the same command "
                                    "again to resume")
            points = instrument.measure(store.measurements_taken, f"{phase} calibration, {label}")
            driver.confirm_still(settled)
            store.add_validation(step, points, calibration_id)
            progress.step(total - len(store.validation_steps_left(phase)), label)
        progress.finish()


def _measure_postures(driver: PlatformDriver, store: CampaignStore, instrument: Instrument, progress: Progress) -> None:
    """Visit every posture not measured yet, leg by leg; the platform ends unlocked."""
    postures, geometry = store.postures, store.geometry
    if store.postures_measured == len(postures):
        return
    progress.start("postures", len(postures), store.postures_measured)
    locked, length = None, 0.0
    try:
        for number in range(store.postures_measured, len(postures)):
            posture = postures[number]
            leg = posture.leg
            if locked != leg:
                if locked is not None:
                    driver.unlock()
                    locked = None
                # The plan locks each leg at its length in the zero posture, on this geometry.
                _to_zero(driver, f"where leg {leg} is to be locked")
                record = driver.lock(leg)
                locked, length = leg, float(lengths_from_readings(geometry.legs, record["leg_setpoints"][leg - 1], leg - 1))
            record = _visit(driver, geometry, leg, length, posture.pose)
            points = instrument.measure(store.measurements_taken, f"posture {number + 1}, leg {leg} locked")
            driver.confirm_still(record)
            store.add_posture(leg, record["leg_feedback"], points)
            progress.step(store.postures_measured, f"leg {leg} locked")
    except CampaignError as error:
        # A controller in fault refuses the unlock; the reset, or the resumed campaign, unlocks.
        if locked is not None and not isinstance(error, ControllerFault):
            _unlock_quietly(driver)
        raise
    driver.unlock()
    progress.finish()


def _unlock_quietly(driver: PlatformDriver) -> None:
    """Unlock the leg a stopped campaign locked, if the service still takes it: the error
    that stopped the campaign is the one to report, and a resumed campaign unlocks first."""
    try:
        driver.unlock()
    except (CampaignError, CommandError, ServiceUnavailable):
        pass


def _visit(driver: PlatformDriver, geometry: Geometry, leg: int, length_mm: float, goal: Sequence[float]) -> Record:
    """Move in leg-lock mode to ``goal`` and settle there; returns the settled record.

    Straight, if the controller takes the move; if it refuses it as one it could not keep
    the locked leg's length along (``lock_unreachable``: far from the constraint, fast) or
    as out of limits (``path_violation``), along :func:`locked_path`, whose pieces stay near
    the constraint; if it refuses that as out of limits, by way of the zero posture (it
    lies on the constraint). A refusal happens at planning, before anything moves; a route
    refused midway goes on from where the platform stopped."""
    routes: list[tuple[Callable[[Sequence[float]], list[Sequence[float]]], tuple[str, ...]]] = [
        (lambda here: [goal], ("lock_unreachable", "path_violation")),
        (lambda here: locked_path(geometry, leg, length_mm, here, goal), ("path_violation",)),
        (lambda here: locked_path(geometry, leg, length_mm, here, ZERO_POSE)
         + locked_path(geometry, leg, length_mm, ZERO_POSE, goal), ()),
    ]
    for route, next_route_on in routes:
        try:
            return _follow(driver, route(driver.status()["pose_command"]))
        except CommandError as error:
            if error.code not in next_route_on:
                raise CampaignError(f"the controller refused the leg-lock move to {list(goal)}: {error}") from None
    raise AssertionError("unreachable: the last route raises or returns")


def _follow(driver: PlatformDriver, waypoints: Sequence[Sequence[float]]) -> Record:
    """Move through ``waypoints``, stopping at each; settle at the last."""
    for waypoint in waypoints[:-1]:
        driver.move(waypoint, settle=False)
    return driver.move(waypoints[-1])


def _identify(store: CampaignStore, options: IdentificationOptions, progress: Progress
              ) -> tuple[IdentificationResult, Geometry, str]:
    """Identify from the saved measurement file (what ``hexactl calibrate`` would use) and
    write the calibration file; returns the result, the calibration and its text."""
    geometry = store.geometry
    try:
        measured = store.measurement_file()
    except MeasurementFileError as error:
        raise CampaignError(str(error)) from None
    sigma = geometry.measurement.point_sigma_mm if options.point_sigma_mm is None else options.point_sigma_mm
    screened = measured.problems + screen_measurements(measured.data, np.array(geometry.measurement.feature_points), sigma,
                                                       legs=geometry.legs, stroke_mm=geometry.limits.stroke,
                                                       zero_readings_mm=geometry.zero_readings_mm())
    problems = blocking_problems(screened, options.method)
    for problem in screened:
        if problem not in problems:
            progress.say(f"{measured.source}: {problem} (left to full, which tests each observation)")
    if problems:
        lines = "\n".join(f"{measured.source}: {problem}" for problem in problems)
        raise CampaignError(f"{lines}\nthe measurements have {len(problems)} problem(s): calibrate with hexactl calibrate "
                            f"{measured.source} --skip-bad-rows, or measure those postures again")
    result = identify(measured.data, geometry, options)
    progress.say(f"identification: {result.reason}")
    if not result.ok:
        raise CampaignError(f"identification {result.status.text}: "
                            + "; ".join(result.warnings) + f" (the data are in {measured.source})")
    predicted = result.predicted
    progress.say(f"fit residual RMS {result.residual_rms_mm:.4f} mm (noise model {result.expected_rms_mm:.4f} mm), "
                 f"{result.consistency}; predicted pose uncertainty {predicted.rms_position_mm:.4f} mm, "
                 f"{predicted.rms_orientation_deg:.5f}° RMS per axis")
    for sentence in extra_estimates(result):
        progress.say(f"also estimated: {sentence}")
    for warning in result.warnings:
        progress.say(f"warning: {warning}")
    for observation in result.excluded:
        progress.say(f"excluded as a {observation.kind}: {observation}")
    path = store.path(CALIBRATION_FILE)
    calibrated = _saved_calibration(path, measured.sha256)
    if calibrated is None:
        created = datetime.now(timezone.utc).isoformat(timespec="seconds")
        info = calibration_info(result, created, measured.sha256, geometry.name or "unnamed geometry")
        calibrated = calibration_geometry(geometry, result, info)
        with saving(path):
            save_geometry(calibrated, path, overwrite=True)  # derived from the saved data: a stale one is replaced
        progress.say(f"wrote {path}")
    return result, calibrated, path.read_text(encoding="utf-8")


def _saved_calibration(path: Path, input_sha256: str) -> Geometry | None:
    """The calibration file a resumed campaign wrote from these very data (the same
    parameters: identification is deterministic), so that its id, which the controller
    may already run, stays the same; None if there is none."""
    try:
        saved = load_geometry(path)
    except GeometryError:  # none, or not readable: written anew
        return None
    return saved if saved.calibration is not None and saved.calibration.input_sha256 == input_sha256 else None


def _show(before: Sequence[MotionResult], after: Sequence[MotionResult], better: bool, progress: Progress) -> None:
    """Each test motion's largest errors before and after, and the verdict."""
    progress.say(f"{'largest error':<14}{'before calibration':>24}{'after calibration':>24}")
    for b_motion, a_motion in zip(before, after):
        b, a = summarise_validation([b_motion]), summarise_validation([a_motion])
        progress.say(f"{b_motion.motion.name:<14}{b.max_position_error_mm:12.3f} mm {b.max_orientation_error_deg:7.4f}°"
                     f"{a.max_position_error_mm:12.3f} mm {a.max_orientation_error_deg:7.4f}°")
    b, a = summarise_validation(before), summarise_validation(after)
    verdict = "improved" if better else "NOT improved"
    progress.say(f"largest error over the test motions: {b.max_position_error_mm:.3f} mm → {a.max_position_error_mm:.3f} mm, "
                 f"{b.max_orientation_error_deg:.4f}° → {a.max_orientation_error_deg:.4f}°: {verdict}")


def campaign_report(result: IdentificationResult, calibration_id: str, before: Sequence[MotionResult],
                    after: Sequence[MotionResult], better: bool) -> dict[str, object]:
    """The finished campaign's results as the API's ``CampaignReport`` (for displays)."""
    parameters, std = result.parameters, result.std

    def flat(values: StructuralParameters) -> list[float]:
        per_leg = np.hstack((values.base_joints_mm, values.platform_joints_mm, values.zero_lengths_mm[:, None]))
        scales = [] if values.scale_errors is None else list(values.scale_errors)
        return [*per_leg.ravel().tolist(), *scales]

    estimates = [{"name": name, "value": value, "sigma": sigma if np.isfinite(sigma) else None}
                 for name, value, sigma in zip(parameter_names(parameters.has_scales), flat(parameters), flat(std))]
    validation = []
    for b_motion, a_motion in zip(before, after):
        b, a = summarise_validation([b_motion]), summarise_validation([a_motion])
        validation.append({"motion": b_motion.motion.name, "before_position_mm": b.max_position_error_mm,
                           "before_orientation_deg": b.max_orientation_error_deg,
                           "after_position_mm": a.max_position_error_mm, "after_orientation_deg": a.max_orientation_error_deg})
    return {"method": str(result.method.value), "calibration_id": calibration_id, "postures": result.postures_used,
            "residual_rms_mm": result.residual_rms_mm, "expected_rms_mm": result.expected_rms_mm,
            "fit": result.consistency, "parameters": estimates, "validation": validation, "improved": better,
            "warnings": list(result.warnings)[:20]}


def _conclude(driver: PlatformDriver, store: CampaignStore, better: bool, apply: bool, progress: Progress) -> None:
    """Keep the calibration (``apply`` and ``better``) or roll back to the planned geometry."""
    if apply and better:
        progress.say(f"the calibration stays active; to start with it after a restart: hexactl serve --calibration "
                     f"{store.path(CALIBRATION_FILE)}")
        return
    driver.prepare()
    planned = geometry_id(store.geometry)
    if driver.status()["calibration_id"] == planned:
        return  # rolled back already (a fault came after it)
    driver.return_to_calibration(planned, geometry_to_toml(store.geometry),
                                 as_one_line(f"hexactl campaign: the geometry {store.path(PLAN_FILE)} was planned on"))
    why = "it did not improve the accuracy" if apply else "--apply keeps it"
    progress.say(f"rolled back to the geometry the campaign started on ({why})")
