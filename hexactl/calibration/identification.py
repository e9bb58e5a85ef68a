"""Identification entry point: pick the method, run it, describe the result for the file.

``auto`` runs ``full`` (maximum likelihood from everything measured, gross mis-sightings
excluded), with the six sensor scale errors when the data show them (a likelihood-ratio
test against exact sensors). Its residuals are then tested against the noise model: if they are too large
(χ²/dof above ``consistency_limit``) while every leg has enough locked postures and
``leglock``'s fit is consistent, the free legs' readings are what disagrees with the
measured poses (a drifting sensor offset, joint play). ``leglock``, which trusts only each
locked leg's constant reading, is chosen then only if its own predicted accuracy is no worse
than ``full``'s (whose uncertainty is already scaled up by its excess χ²): ``auto`` never
takes a method its own diagnostics say is worse. The explanation is in the result's
``reason``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from hexactl.calibration.data import MeasurementData
from hexactl.calibration.full import identify_full
from hexactl.calibration.leglock import identify_leglock, too_few_locked
from hexactl.calibration.paper import identify_paper
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, Method
from hexactl.kinematics.geometry import CalibrationInfo, Geometry, geometry_from_mapping
from hexactl.kinematics.inverse import LEG_COUNT

_METHODS = {Method.FULL: identify_full, Method.LEGLOCK: identify_leglock, Method.PAPER: identify_paper}

SCALE_TEST_FALSE_ALARM = 0.01
"""``auto`` identifies sensor scale errors when they improve the fit more than exact sensors
would by chance with this probability."""


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
        return _identify(data, nominal, options)
    gains = nominal.legs.sensor_gains
    exact = geometry_from_mapping({**nominal.model_dump(), "sensor_scale_errors": (0.0,) * 6}, "nominal geometry")
    result = _identify(replace(data, readings_mm=data.readings_mm * gains), exact, options)
    identified = result.parameters.scale_errors
    if identified is None:
        return result
    return replace(result, parameters=replace(result.parameters, scale_errors=gains * (1.0 + identified) - 1.0))


def _identify(data: MeasurementData, nominal: Geometry, options: IdentificationOptions) -> IdentificationResult:
    if options.method is not Method.AUTO:
        return _METHODS[options.method](data, nominal, options)
    full, scales_note = _full_with_scales_if_significant(data, nominal, options)
    excluded = f"; {len(full.excluded)} mis-sighted observation(s) excluded" if full.excluded else ""
    consistent = full.ok and full.chi2_per_dof <= options.consistency_limit
    if consistent:
        return replace(full, reason=f"auto chose full: every posture's pose and all six readings are used at once "
                       f"(maximum likelihood, {len(data)} postures{excluded}); the residuals agree with the noise model "
                       f"(χ²/dof {full.chi2_per_dof:.3g} ≤ {options.consistency_limit:g}){scales_note}")
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
                           f"uncertainty scaled up by its excess χ²){scales_note}")
    return replace(full, reason=f"auto chose full, although its residuals do not match the noise model "
                   f"(χ²/dof {full.chi2_per_dof:.3g}{excluded}) and leglock offers nothing better for these data{scales_note}")


def _full_with_scales_if_significant(data: MeasurementData, nominal: Geometry,
                                     options: IdentificationOptions) -> tuple[IdentificationResult, str]:
    """``full``, with sensor scale errors when asked or when the data show them, and why (for
    the reason). The test is the likelihood ratio (χ², 6 dof) at :data:`SCALE_TEST_FALSE_ALARM`,
    with the χ² drop divided by the scaled fit's χ²/dof where that exceeds 1: a misfit of
    another kind (a sliding sensor) lowers χ² with any added freedom, and must not pass for
    a gain (as the covariance is scaled up by the same factor)."""
    full = identify_full(data, nominal, options)
    if options.estimate_scales or not full.ok:
        return full, ""
    scaled = identify_full(data, nominal, replace(options, estimate_scales=True))
    threshold = float(chi2.isf(SCALE_TEST_FALSE_ALARM, LEG_COUNT))
    drop = (full.chi2 - scaled.chi2) / max(1.0, scaled.chi2_per_dof)
    if not (scaled.ok and drop > threshold):  # also false for NaN (no redundancy)
        return full, ""
    return scaled, (f"; sensor scale errors identified: they lower χ² by {drop:.1f}, more than exact sensors would "
                    f"by chance ({threshold:.1f} at probability {SCALE_TEST_FALSE_ALARM:g})")


def _no_worse(candidate: IdentificationResult, reference: IdentificationResult) -> bool:
    """Whether ``candidate`` predicts test-motion errors no larger than ``reference``, in
    position and in orientation."""
    return (candidate.predicted.rms_position_mm <= reference.predicted.rms_position_mm
            and candidate.predicted.rms_orientation_deg <= reference.predicted.rms_orientation_deg)


def _accuracy(result: IdentificationResult) -> str:
    return f"{result.predicted.rms_position_mm:.3g} mm, {result.predicted.rms_orientation_deg:.3g}° RMS"


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
        notes=result.reason + "".join(f"; excluded as a mis-sighting: {observation}" for observation in result.excluded),
    )


def _rows(values: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(row[0]), float(row[1]), float(row[2])) for row in values)


def _six(values: np.ndarray) -> tuple[float, float, float, float, float, float]:
    a, b, c, d, e, f = (float(v) for v in values)
    return (a, b, c, d, e, f)
