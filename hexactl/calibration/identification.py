"""Identification entry point: pick the method, run it, describe the result for the file.

``auto`` runs ``full`` (maximum likelihood from everything measured). Its residuals are
then tested against the noise model: if they are too large (χ²/dof above
``consistency_limit``) while every leg has enough locked postures and ``leglock``'s fit is
consistent, the free legs' readings are what disagrees with the measured poses (a
drifting sensor offset, joint play), and ``leglock``, which trusts only each locked leg's
constant reading, is chosen. The explanation is in the result's ``reason``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hexactl.calibration.data import MeasurementData
from hexactl.calibration.full import identify_full
from hexactl.calibration.leglock import identify_leglock, too_few_locked
from hexactl.calibration.paper import identify_paper
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, Method
from hexactl.kinematics.geometry import CalibrationInfo, Geometry

_METHODS = {Method.FULL: identify_full, Method.LEGLOCK: identify_leglock, Method.PAPER: identify_paper}


def identify(data: MeasurementData, nominal: Geometry, options: IdentificationOptions = IdentificationOptions()) -> IdentificationResult:
    """Identify the structural parameters from ``data``, starting at ``nominal``.

    Screen the data first (:func:`hexactl.calibration.data.screen_measurements`): this
    function trusts every row it is given. Never raises for bad data: the result's status
    and warnings say what went wrong.
    """
    if options.method is not Method.AUTO:
        return _METHODS[options.method](data, nominal, options)
    full = identify_full(data, nominal, options)
    consistent = full.ok and full.chi2_per_dof <= options.consistency_limit
    if consistent:
        return replace(full, reason=f"auto chose full: every posture's pose and all six readings are used at once "
                       f"(maximum likelihood, {len(data)} postures); the residuals agree with the noise model "
                       f"(χ²/dof {full.chi2_per_dof:.3g} ≤ {options.consistency_limit:g})")
    if too_few_locked(data) is None:
        leglock = identify_leglock(data, nominal, options)
        if leglock.ok and leglock.chi2_per_dof <= options.consistency_limit:
            return replace(leglock, reason=f"auto chose leglock: the full fit's residuals do not match the noise "
                           f"model (χ²/dof {full.chi2_per_dof:.3g}) while each locked leg alone does "
                           f"(χ²/dof {leglock.chi2_per_dof:.3g}): the free legs' readings disagree with the measured "
                           f"poses (sensor offset drift, joint play?), so only the locked legs are trusted")
    return replace(full, reason=f"auto chose full, although its residuals do not match the noise model "
                   f"(χ²/dof {full.chi2_per_dof:.3g}) and leglock offers nothing better for these data")


def calibration_info(result: IdentificationResult, created: str, input_sha256: str, nominal_name: str) -> CalibrationInfo:
    """The ``[calibration]`` table for ``result``; ``created`` ISO 8601, the hash of the input file."""
    std = result.std
    scales = result.parameters.scale_errors
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
        sensor_scale_errors=None if scales is None else _six(scales),
        notes=result.reason,
    )


def _rows(values: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(row[0]), float(row[1]), float(row[2])) for row in values)


def _six(values: np.ndarray) -> tuple[float, float, float, float, float, float]:
    a, b, c, d, e, f = (float(v) for v in values)
    return (a, b, c, d, e, f)
