"""Identification entry point: pick the method, run it, describe the result for the file.

``auto`` runs ``full`` (maximum likelihood from everything measured, gross mis-sightings
and wrong readings excluded), with the six sensor scale errors and each sensor offset's
drift over the campaign when the data show them (likelihood-ratio tests). Its residuals are then tested against the noise model: if they are too large
(χ²/dof above ``consistency_limit``) while every leg has enough locked postures and
``leglock``'s fit is consistent, the free legs' readings are what disagrees with the
measured poses (a drifting sensor offset, joint play). ``leglock``, which trusts only each
locked leg's constant reading, is chosen then only if its own predicted accuracy is no worse
than ``full``'s (whose uncertainty is already scaled up by its excess χ²): ``auto`` never
takes a method its own diagnostics say is worse. The explanation is in the result's
``reason``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from hexactl.calibration.data import MeasurementData, RowProblem
from hexactl.calibration.full import identify_full, observation_key
from hexactl.calibration.leglock import identify_leglock, too_few_locked
from hexactl.calibration.paper import identify_paper
from hexactl.calibration.parameters import PARAMETERS_PER_LEG, calibrated_geometry
from hexactl.calibration.results import (IdentificationOptions, IdentificationResult, IdentificationStatus, Method,
                                         excluded_summary)
from hexactl.kinematics.geometry import CalibrationInfo, Geometry, geometry_from_mapping
from hexactl.kinematics.inverse import LEG_COUNT
from hexactl.kinematics.plausibility import parameter_implausibilities

_METHODS = {Method.FULL: identify_full, Method.LEGLOCK: identify_leglock, Method.PAPER: identify_paper}

EXTRA_TEST_FALSE_ALARM = 0.01
"""``auto`` identifies sensor scale errors, and offset drift, when they improve the fit more
than their absence would by chance with this probability."""


def identify(data: MeasurementData, nominal: Geometry, options: IdentificationOptions = IdentificationOptions()) -> IdentificationResult:
    """Identify the structural parameters from ``data``, starting at ``nominal``.

    Screen the data first (:func:`hexactl.calibration.data.screen_measurements`): this
    function trusts every row it is given. Never raises for bad data: the result's status
    and warnings say what went wrong.

    A ``nominal`` with sensor scale errors (a calibration being redone) keeps them: the
    methods model exact sensors plus the scale errors they identify, so they are given the
    readings the nominal's gains turn into lengths, and any scale errors identified are
    composed with the nominal's in the result.
    """
    if not np.any(nominal.legs.sensor_scale_errors):
        return _plausible(_identify(data, nominal, options), nominal)
    gains = nominal.legs.sensor_gains
    exact = geometry_from_mapping({**nominal.model_dump(), "sensor_scale_errors": (0.0,) * 6}, "nominal geometry")
    result = _identify(replace(data, readings_mm=data.readings_mm * gains), exact, options)
    identified = result.parameters.scale_errors
    if identified is not None:
        result = replace(result, parameters=replace(result.parameters, scale_errors=gains * (1.0 + identified) - 1.0))
    return _plausible(result, nominal)


_DATA_CHECKS = ("check their units (mm, degrees), that the instrument's frame is the platform's base frame, and the "
                "rows flagged above")
"""What to check when the data do not measure the nominal platform as they should."""


GROSS_MISFIT_CHI2_PER_DOF = 1e4
"""χ²/dof beyond which residuals (100× the noise model) are not noise or a lack of postures
but data that do not measure the platform (another frame or unit): found from outside, a
tracker frame turned 90° gave χ²/dof 8e5 and "not observable: add postures", which no
posture could help."""


def _plausible(result: IdentificationResult, nominal: Geometry) -> IdentificationResult:
    """``result``, or IMPLAUSIBLE when its parameters lie beyond the nominal's plausibility
    bounds, which the controller refuses to load: data that fit a machine that far from
    the design are wrong (another unit or frame, targets swapped), not a calibration. A fit
    that did not converge is told what to check too (a frame turned 180° is found no other
    way), and a plausible one whose base moved as a whole is warned of
    (:func:`_base_motion_warning`)."""
    if result.status is IdentificationStatus.NOT_CONVERGED:
        return replace(result, warnings=result.warnings + (
            f"the fit found no minimum from the nominal platform: the data may not measure it as they should; "
            f"{_DATA_CHECKS}",))
    if result.status is IdentificationStatus.NOT_OBSERVABLE and result.chi2_per_dof > GROSS_MISFIT_CHI2_PER_DOF:
        return replace(result, warnings=(  # first: the advice to add postures that follows cannot help yet
            f"residuals {np.sqrt(result.chi2_per_dof):.3g}× the noise model are no lack of postures: the data do not "
            f"measure the nominal platform as they should; {_DATA_CHECKS}, before adding postures",) + result.warnings)
    if not result.ok:
        return result
    parameters = result.parameters
    if not (problems := parameter_implausibilities(
            parameters.base_joints_mm, parameters.platform_joints_mm, parameters.zero_lengths_mm, nominal)):
        moved = _base_motion_warning(result, nominal)
        return result if moved is None else replace(result, warnings=result.warnings + (moved,))
    shown = "; ".join(problems[:3]) + (f"; and {len(problems) - 3} more" if len(problems) > 3 else "")
    return replace(result, status=IdentificationStatus.IMPLAUSIBLE, warnings=result.warnings + (
        f"the identified parameters are not this machine's: {shown}; the controller refuses such a calibration. "
        f"The data do not measure the nominal platform as they should: {_DATA_CHECKS}",))


BASE_MOTION_SIGMAS = 5.0
"""The base's common rigid motion is warned of where its Mahalanobis length (the rigid motion's
six parameters against their covariance) exceeds this: noise alone does so with probability
3e-4 (χ² with 6 dof above 25)."""

BASE_MOTION_DOMINANCE = 3.0
"""... and where its RMS displacement over the joints exceeds this many times the RMS of the
joints' other deviations: not manufacturing scatter. Independent isotropic joint errors put 6
of their 18 degrees of freedom in the rigid part (RMS ratio about 0.7) and exceed 3 with
probability 2e-5 (F(6, 12) > 18); a frame error moves every joint alike and leaves the rest."""


def _base_motion_warning(result: IdentificationResult, nominal: Geometry) -> str | None:
    """A warning when the identified base joints are mostly the nominal ones moved as one
    rigid body (:data:`BASE_MOTION_SIGMAS`, :data:`BASE_MOTION_DOMINANCE`): the signature of
    data measured in a frame other than the base frame, which the fit cannot see (the
    platform joints and zero lengths, in the moving frame, are unaffected); None otherwise.
    The rigid motion is the least-squares one, linearised (a plausible result's base turns
    by a few degrees at most)."""
    designed = np.array(nominal.base_joints)
    deviations = (result.parameters.base_joints_mm - designed).ravel()  # (18,) mm
    arms = designed - designed.mean(axis=0)
    # Each joint's displacement by a translation t and a small rotation ω about the joints' centre: t + ω × arm.
    turns = np.cross(np.eye(3)[None, :, :], arms[:, None, :]).transpose(0, 2, 1).reshape(-1, 3)  # (18, 3): ∂/∂ω
    motions = np.concatenate((np.tile(np.eye(3), (LEG_COUNT, 1)), turns), axis=1)
    fit = np.linalg.pinv(motions)  # (6, 18): the rigid motion (mm, rad) that best explains given deviations
    motion = fit @ deviations
    columns = (PARAMETERS_PER_LEG * np.arange(LEG_COUNT)[:, None] + np.arange(3)).ravel()  # base joints' x, y, z
    motion_covariance = fit @ result.covariance[np.ix_(columns, columns)] @ fit.T
    sigmas = float(np.sqrt(motion @ np.linalg.pinv(motion_covariance) @ motion))
    rigid = (motions @ motion).reshape(LEG_COUNT, 3)
    distances = np.linalg.norm(rigid, axis=1)
    rest = deviations.reshape(LEG_COUNT, 3) - rigid
    if not (sigmas > BASE_MOTION_SIGMAS
            and np.sqrt(np.mean(distances**2)) > BASE_MOTION_DOMINANCE * np.sqrt(np.mean(np.sum(rest**2, axis=1)))):
        return None
    return (f"the base moved as a whole by {np.min(distances):.1f} to {np.max(distances):.1f} mm at its joints and "
            f"turned {np.degrees(np.linalg.norm(motion[3:])):.2f}° ({sigmas:.0f} σ): that is the instrument's frame "
            "not being the base frame, not the base; measure the base's reference points in the instrument's frame "
            "and transform the data into the base frame (docs/calibration.md, measurement files)")


def _identify(data: MeasurementData, nominal: Geometry, options: IdentificationOptions) -> IdentificationResult:
    if options.method is Method.FULL:
        return _full_warning_of_extras(data, nominal, options)
    if options.method is not Method.AUTO:
        return _METHODS[options.method](data, nominal, options)
    full, extras_note = _full_with_significant_extras(data, nominal, options)
    excluded = f"; {excluded_summary(full.excluded)}" if full.excluded else ""
    consistent = full.ok and full.chi2_per_dof <= options.consistency_limit
    if consistent:
        return replace(full, reason=f"auto chose full: every posture's pose and all six readings are used at once "
                       f"(maximum likelihood, {_postures(full, data)}{excluded}); its residuals are within the noise "
                       f"model's consistency limit (χ²/dof {full.chi2_per_dof:.3g} ≤ {options.consistency_limit:g})"
                       f"{extras_note}")
    if too_few_locked(data) is None:
        leglock = identify_leglock(data, nominal, options)
        if leglock.ok and leglock.chi2_per_dof <= options.consistency_limit:
            if not full.ok or _no_worse(leglock, full):
                return replace(leglock, reason=f"auto chose leglock: the full fit's residuals do not match the noise "
                               f"model (χ²/dof {full.chi2_per_dof:.3g}{excluded}) while each locked leg alone does "
                               f"(χ²/dof {leglock.chi2_per_dof:.3g}) and predicts no worse an accuracy "
                               f"({_accuracy(leglock)} against full's {_accuracy(full)}): the free legs' readings "
                               f"disagree with the measured poses (sensor offset drift, joint play?), so only the "
                               f"locked legs are trusted")
            return replace(full, reason=f"auto chose full, although its residuals do not match the noise model "
                           f"(χ²/dof {full.chi2_per_dof:.3g}{excluded}): leglock fits its locked legs consistently but "
                           f"predicts a worse accuracy ({_accuracy(leglock)} against full's {_accuracy(full)}, full's "
                           f"uncertainty scaled up by its excess χ²){extras_note}")
    if not full.ok:  # nothing fitted: no residuals to speak of (χ²/dof is NaN)
        return replace(full, reason=f"auto tried full, which identified nothing "
                       f"({full.status.text}), and leglock offers nothing better for these data")
    return replace(full, reason=f"auto chose full, although its residuals do not match the noise model "
                   f"(χ²/dof {full.chi2_per_dof:.3g}{excluded}) and leglock offers nothing better for these data{extras_note}")


EXTRAS = (("estimate_scales", "sensor scale errors", "--scales"), ("estimate_drift", "sensor offset drift", None))
"""What ``full`` may add to the structural parameters, tested in this order."""


def _significant_extra(data: MeasurementData, nominal: Geometry, options: IdentificationOptions,
                       full: IdentificationResult, option: str, richer: IdentificationResult | None = None,
                       ) -> tuple[IdentificationResult, float, float] | None:
    """``full`` refitted with ``option`` (an :data:`EXTRAS` flag) when the data show it
    (richer result, χ² drop, threshold); None otherwise. The test is the likelihood ratio
    (χ², 6 dof) at :data:`EXTRA_TEST_FALSE_ALARM`, with the χ² drop divided by the richer
    fit's χ²/dof where that exceeds 1: a misfit of another kind (a sliding sensor) lowers χ²
    with any added freedom, and must not pass for a gain or a drift (as the covariance is
    scaled up by the same factor). Nor is an extra taken whose fit still does not match the
    noise model (χ²/dof above ``consistency_limit``): with the noise figures off, the test
    says nothing (found from outside: noise 0.3 and 1 mm given as 0.25, χ²/dof 6, and a
    drift "identified" at 9 σ that the platform did not have; the residuals' note says to
    give the noise figures). The two fits are compared on the same observations:
    where their searches for gross errors excluded different ones, both are fitted again
    without any either excluded (else a mis-sighting one of them left out would count as the
    extra's drop in χ²). ``richer``: the refit with the extra, where it is at hand."""
    if getattr(options, option) or not full.ok:
        return None
    richer_options = replace(options, **{option: True})
    richer = richer if richer is not None else identify_full(data, nominal, richer_options)
    simpler, compared = full, richer
    full_left_out, richer_left_out = ({observation_key(e) for e in fit.excluded} for fit in (full, richer))
    if richer.ok and full_left_out != richer_left_out:
        left_out = full_left_out | richer_left_out
        simpler = identify_full(data, nominal, options, left_out=left_out)
        compared = identify_full(data, nominal, richer_options, left_out=left_out)
    threshold = float(chi2.isf(EXTRA_TEST_FALSE_ALARM, LEG_COUNT))
    drop = (simpler.chi2 - compared.chi2) / max(1.0, compared.chi2_per_dof)
    consistent = compared.chi2_per_dof <= options.consistency_limit
    return (richer, drop, threshold) if richer.ok and compared.ok and consistent and drop > threshold else None  # NaN too


def _full_with_significant_extras(data: MeasurementData, nominal: Geometry,
                                  options: IdentificationOptions) -> tuple[IdentificationResult, str]:
    """``full``, with sensor scale errors and then offset drift when asked or when the data
    show them (:func:`_significant_extra`), and why (for the reason). An extra taken
    before a later one is tested again with the later one in the model, and dropped unless
    still significant: unmodelled, a drift's misfit is partly a gain's."""
    full = identify_full(data, nominal, options)
    found: dict[str, tuple[float, float]] = {}  # option: (χ² drop, threshold)
    for option, _, _ in EXTRAS:
        if (extra := _significant_extra(data, nominal, options, full, option)) is not None:
            full, drop, threshold = extra
            options = replace(options, **{option: True})
            found[option] = drop, threshold
    for option in list(found)[:-1]:
        without = replace(options, **{option: False})
        fewer = identify_full(data, nominal, without)
        if (extra := _significant_extra(data, nominal, without, fewer, option, richer=full)) is None:
            full, options = fewer, without
            del found[option]
        else:
            found[option] = extra[1:]
    notes = "".join(f"; {what} identified: they lower χ² by {found[option][0]:.1f}, more than their absence would by "
                    f"chance ({found[option][1]:.1f} at probability {EXTRA_TEST_FALSE_ALARM:g})"
                    for option, what, _ in EXTRAS if option in found)
    return full, notes


def _full_warning_of_extras(data: MeasurementData, nominal: Geometry,
                            options: IdentificationOptions) -> IdentificationResult:
    """``full`` as asked, with a warning for each extra the data show but it was not asked
    to identify (the misspecification test of gains and drift)."""
    full = identify_full(data, nominal, options)
    warnings = []
    for option, what, flag in EXTRAS:
        if (found := _significant_extra(data, nominal, options, full, option)) is not None:
            _, drop, threshold = found
            remedy = f"pass {flag} or use --method auto" if flag else "use --method auto, which identifies it"
            warnings.append(f"the data show {what} (modelling it lowers χ² by {drop:.1f}, beyond the {threshold:.1f} "
                            f"chance gives with probability {EXTRA_TEST_FALSE_ALARM:g}): {remedy}")
    return replace(full, warnings=full.warnings + tuple(warnings)) if warnings else full


def _no_worse(candidate: IdentificationResult, reference: IdentificationResult) -> bool:
    """Whether ``candidate`` predicts test-motion errors no larger than ``reference``, in
    position and in orientation."""
    return (candidate.predicted.rms_position_mm <= reference.predicted.rms_position_mm
            and candidate.predicted.rms_orientation_deg <= reference.predicted.rms_orientation_deg)


def _postures(result: IdentificationResult, data: MeasurementData) -> str:
    """How many postures ``result`` used, of how many given when it left some out (all of
    a posture's observations excluded): the count the output's "postures used" gives."""
    given = f" of {len(data)}" if result.postures_used != len(data) else ""
    return f"{result.postures_used}{given} postures"


def _accuracy(result: IdentificationResult) -> str:
    return f"{result.predicted.rms_position_mm:.3g} mm, {result.predicted.rms_orientation_deg:.3g}° RMS per axis"


def calibration_info(result: IdentificationResult, created: str, input_sha256: str, nominal_name: str) -> CalibrationInfo:
    """The ``[calibration]`` table for ``result``; ``created`` ISO 8601, the hash of the input file."""
    std = result.std
    return CalibrationInfo(
        method=str(result.method),
        created=created,
        input_sha256=input_sha256,
        postures=result.postures_used,
        residual_rms_mm=result.residual_rms_mm,
        nominal=nominal_name,
        base_joints_std_mm=_rows(std.base_joints_mm),
        platform_joints_std_mm=_rows(std.platform_joints_mm),
        zero_lengths_std_mm=_six(std.zero_lengths_mm),
        sensor_scale_errors_std=None if std.scale_errors is None else _six(std.scale_errors),
        parameter_covariance=tuple(tuple(float(v) for v in row) for row in result.covariance),
        notes=result.reason + "".join(f"; excluded as a {observation.kind}: {observation}" for observation in result.excluded)
        + "".join(f"; {sentence}" for sentence in extra_estimates(result)),
        status=result.status.text,
        warnings=result.warnings,
    )


def blocking_problems(problems: Sequence[RowProblem], method: Method) -> tuple[RowProblem, ...]:
    """The screening's problems that stop ``method``: all of them, except that ``full`` (and
    ``auto``, which runs it) tests every observation and excludes mis-sightings itself."""
    robust = method in (Method.FULL, Method.AUTO)
    return tuple(problem for problem in problems if not (robust and problem.mis_sighting))


def calibration_geometry(nominal: Geometry, result: IdentificationResult, info: CalibrationInfo) -> Geometry:
    """The calibration file's geometry: ``nominal`` with ``result``'s parameters and, when
    identified, feature points, and ``info`` (:func:`calibration_info`). Raises
    :class:`~hexactl.kinematics.geometry.GeometryError` if it is not a valid geometry."""
    points = result.feature_points_mm
    return calibrated_geometry(nominal, result.parameters, info, None if points is None else points.value)


def extra_estimates(result: IdentificationResult) -> tuple[str, ...]:
    """The drift and feature points ``full`` estimated besides the parameters, a sentence
    each, for people (the calibration file's notes, ``hexactl calibrate``)."""
    sentences = []
    if (drift := result.offset_drift_mm) is not None:
        legs = ", ".join(f"{value:+.3f}±{std:.3f}" for value, std in zip(drift.value, drift.std))
        sentences.append(f"zero lengths drifted over the campaign by (legs 1-6, mm, end minus start) {legs}: the "
                         "file's zero lengths are the campaign's end")
    if (points := result.feature_points_mm) is not None:
        sentences.append("feature points identified (moving frame, mm): " + ", ".join(
            f"p{k} ({x:.3f}, {y:.3f}, {z:.3f})±{np.max(std):.3f}"
            for k, ((x, y, z), std) in enumerate(zip(points.value, points.std), start=1)))
    return tuple(sentences)


def _rows(values: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(row[0]), float(row[1]), float(row[2])) for row in values)


def _six(values: np.ndarray) -> tuple[float, float, float, float, float, float]:
    a, b, c, d, e, f = (float(v) for v in values)
    return (a, b, c, d, e, f)
