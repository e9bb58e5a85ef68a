"""The calibration report: one self-contained HTML page plus its figures as PNG files.

Always: fit statistics, observability, parameter table (deviation from nominal, standard
deviation), residuals per posture, excluded rows and warnings. With validation results
(simulation, or a campaign that measured the test motions): the paper's Fig. 3/4 plots
before and after calibration and its Table 1 for the compound motion. A real-data
``hexactl calibrate`` has no validation (the true platform is unknown); it shows instead
the pose accuracy the parameter uncertainty predicts.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hexactl.adapters.files.atomic import write_atomic
from hexactl.calibration.data import RowProblem
from hexactl.calibration.parameters import StructuralParameters, parameter_names
from hexactl.calibration.results import IdentificationResult
from hexactl.calibration.test_motions import PAPER_TABLE_1, PAPER_TEST_MOTIONS
from hexactl.calibration.uncertainty import PredictedAccuracy
from hexactl.calibration.validation import MotionResult, summarise_validation
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS

REPORT_PAGE = "index.html"

_FIGURES = ("residuals.png", "parameters.png", "observability.png", "accuracy_map.png",
            *(f"{motion.name}.png" for motion in PAPER_TEST_MOTIONS if motion.axis is not None))
"""Every figure a report may write beside its page."""


@dataclass(frozen=True, slots=True)
class ValidationComparison:
    """The test motions run before (``before``, nominal controller) and after calibration,
    in the same motion order; ``bound``: the Cramér–Rao prediction of the after errors."""

    before: tuple[MotionResult, ...]
    after: tuple[MotionResult, ...]
    bound: PredictedAccuracy | None = None


@dataclass(frozen=True, slots=True)
class CalibrationReport:
    """Everything the report shows. ``true`` (simulation only) adds the true parameters."""

    source: str
    created: str
    nominal: Geometry
    result: IdentificationResult
    excluded: tuple[RowProblem, ...] = ()
    validation: ValidationComparison | None = None
    true: Geometry | None = None


def write_report(directory: str | os.PathLike[str], report: CalibrationReport, *, overwrite: bool = False) -> Path:
    """Write the page and its PNGs into ``directory``; returns the page's path.

    Refuses (``FileExistsError``) a directory that already holds a report unless
    ``overwrite``; overwriting removes the figures of the report before that this one
    has not (its validation plots, say). Every file is written atomically.
    """
    # Imported here: matplotlib takes about half a second to import, and the modules that
    # only need REPORT_PAGE (the service's, the CLI's) must not pay for it.
    from hexactl.adapters.report import plots

    folder = Path(directory)
    if (folder / REPORT_PAGE).exists() and not overwrite:
        raise FileExistsError(f"{folder} already holds a report; refusing to overwrite it (use --force)")
    with_scales = report.result.parameters.has_scales
    nominal_vector = _parameter_vector(report.nominal, with_scales)
    true_vector = None if report.true is None else _parameter_vector(report.true, with_scales)
    figures = {
        "residuals.png": plots.residuals_figure(report.result),
        "parameters.png": plots.parameters_figure(report.result, nominal_vector, true_vector),
        "observability.png": plots.observability_figure(report.result),
    }
    if report.result.ok:
        figures["accuracy_map.png"] = plots.accuracy_map_figure(report.result, report.nominal)
    if report.validation is not None:
        for before, after in zip(report.validation.before, report.validation.after):
            if before.motion.axis is not None:
                figures[f"{before.motion.name}.png"] = plots.motion_figure(before, after)
    for name, png in figures.items():
        write_atomic(folder / name, png, overwrite=True)
    for name in set(_FIGURES) - figures.keys():  # left there, they would pass for this calibration's
        (folder / name).unlink(missing_ok=True)
    page = _page(report, figures, nominal_vector, true_vector)
    return write_atomic(folder / REPORT_PAGE, page.encode("utf-8"), overwrite=True)


def _parameter_vector(geometry: Geometry, with_scales: bool) -> np.ndarray:
    """``geometry``'s parameters, with its sensor gains when the result has gains to compare
    them with (a recalibration's nominal, a simulation's truth, carry theirs)."""
    parameters = StructuralParameters.from_geometry(geometry)
    if with_scales:
        parameters = replace(parameters, scale_errors=np.array(geometry.sensor_scale_errors))
    return parameters.to_vector()


def _page(report: CalibrationReport, figures: dict[str, bytes], nominal_vector: np.ndarray,
          true_vector: np.ndarray | None) -> str:
    result = report.result
    sections = [
        f"<h1>Calibration report</h1><p>{_e(report.source)} — {_e(report.created)}</p>",
        _summary(result),
        _warnings(result, report.excluded),
    ]
    if report.validation is not None:
        sections.append(_validation(report.validation, figures))
    sections += [
        "<h2>Parameters</h2>", _parameter_table(result, nominal_vector, true_vector), _img(figures["parameters.png"]),
        "<h2>Residuals per posture</h2>", _img(figures["residuals.png"]),
        "<h2>Observability</h2>", _observability(result), _img(figures["observability.png"]),
    ]
    if "accuracy_map.png" in figures:
        sections += ["<h2>Predicted accuracy over the workspace</h2>",
                     "<p>The 1σ position error of the platform's origin that the parameters' covariance predicts, "
                     "pose by pose, as a radius √(σx² + σy² + σz²) (the controller reports it at the tool point for "
                     "every move: <code>predicted_accuracy.position_mm</code> of <code>validate_pose</code> and "
                     "<code>status</code>).</p>", _img(figures["accuracy_map.png"])]
    style = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
             "th{background:#f2f2f2}td.l,th.l{text-align:left}.warn{background:#fff4e5;padding:.5em 1em}"
             "img{max-width:100%}")
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>hexactl calibration report</title>"
            f"<style>{style}</style></head><body>{''.join(sections)}</body></html>\n")


def _summary(result: IdentificationResult) -> str:
    predicted = result.predicted
    rows = [
        ("status", result.status.text
         + ("" if result.ok else ": no calibration file was written")),
        ("method", f"{result.method} — {result.reason}"),
        ("postures used", str(result.postures_used)),
        ("fit residual RMS", f"{result.residual_rms_mm:.4f} mm (noise model expects {result.expected_rms_mm:.4f} mm)"),
        ("χ² / degrees of freedom", f"{result.consistency} (≈ 1 when the residuals match the noise model)"),
        ("iterations", str(result.iterations)),
        ("predicted pose uncertainty on the test motions, per axis",
         f"{predicted.rms_position_mm:.4f} mm per position axis (x, y, z), {predicted.rms_orientation_deg:.5f}° per "
         f"angle (roll, pitch, yaw), RMS (1σ); as a radius √(σx² + σy² + σz²), what status's "
         f"predicted_accuracy.position_mm gives at the platform's origin: {np.sqrt(3.0) * predicted.rms_position_mm:.4f} mm "
         f"RMS; expected largest on one axis {predicted.expected_max_position_mm:.4f} mm, "
         f"{predicted.expected_max_orientation_deg:.5f}°" if result.observability.full_rank else
         "not predicted: the data do not determine every parameter (what they determine alone would give a figure "
         "far too small)"),
    ]
    return "<h2>Summary</h2><table>" + "".join(f"<tr><th class='l'>{_e(k)}</th><td class='l'>{_e(v)}</td></tr>" for k, v in rows) + "</table>"


def _warnings(result: IdentificationResult, excluded: Sequence[RowProblem]) -> str:
    items = [f"<li>{_e(w)}</li>" for w in result.warnings]
    items += [f"<li>excluded: {_e(str(problem))}</li>" for problem in excluded]
    items += [f"<li>excluded as a {observation.kind}: {_e(str(observation))}</li>" for observation in result.excluded]
    return f"<div class='warn'><h3>Warnings</h3><ul>{''.join(items)}</ul></div>" if items else ""


def _validation(validation: ValidationComparison, figures: dict[str, bytes]) -> str:
    before, after = summarise_validation(validation.before), summarise_validation(validation.after)
    rows = [("largest position error, mm", before.max_position_error_mm, after.max_position_error_mm),
            ("largest orientation error, deg", before.max_orientation_error_deg, after.max_orientation_error_deg),
            ("RMS position error, mm", before.rms_position_error_mm, after.rms_position_error_mm),
            ("RMS orientation error, deg", before.rms_orientation_error_deg, after.rms_orientation_error_deg)]
    out = ["<h2>Validation: commanded against achieved poses</h2><table><tr><th class='l'></th><th>before</th><th>after</th></tr>"]
    out += [f"<tr><th class='l'>{name}</th><td>{b:.4f}</td><td>{a:.4f}</td></tr>" for name, b, a in rows]
    out.append("</table>")
    if validation.bound is not None:
        bound = validation.bound
        out.append(f"<p>Cramér–Rao prediction for the after errors: largest {bound.expected_max_position_mm:.4f} mm and "
                   f"{bound.expected_max_orientation_deg:.5f}° (expected), RMS {bound.rms_position_mm:.4f} mm and "
                   f"{bound.rms_orientation_deg:.5f}°.</p>")
    for b, a in zip(validation.before, validation.after):
        if b.motion.axis is not None:
            out.append(f"<h3>{_e(b.motion.title)}</h3>{_img(figures[f'{b.motion.name}.png'])}")
        else:
            out.append(_compound_table(b, a))
    return "".join(out)


def _compound_table(before: MotionResult, after: MotionResult) -> str:
    header = "".join(f"<th>{axis} ({unit})</th>" for axis, unit in zip(POSE_AXES, POSE_UNITS))
    rows = [("instruction", before.commanded_relative[-1]), ("result before calibration", before.achieved_relative[-1]),
            ("result after calibration", after.achieved_relative[-1])]
    body = "".join(f"<tr><th class='l'>{name}</th>{''.join(f'<td>{v:.3f}</td>' for v in values)}</tr>" for name, values in rows)
    paper = "".join(f"<tr><th class='l'>paper: {_e(name)}</th>{''.join(f'<td>{v:.2f}</td>' for v in values)}</tr>"
                    for name, values in PAPER_TABLE_1.items())
    return (f"<h3>{_e(before.motion.title)}</h3><table><tr><th class='l'></th>{header}</tr>{body}</table>"
            f"<p>For comparison, the paper's Table 1 (its platform and theodolites):</p>"
            f"<table><tr><th class='l'></th>{header}</tr>{paper}</table>")


def _parameter_table(result: IdentificationResult, nominal_vector: np.ndarray, true_vector: np.ndarray | None) -> str:
    estimate = result.parameters.to_vector()
    std = result.std_vector
    names = parameter_names(result.parameters.has_scales)
    extra = "<th>true − identified</th><th>error / σ</th>" if true_vector is not None else ""
    rows = []
    for k, name in enumerate(names):
        nominal = nominal_vector[k]
        sigma = f"{std[k]:.3f}" if np.isfinite(std[k]) else "not determined"
        cells = f"<td>{nominal:.3f}</td><td>{estimate[k]:.3f}</td><td>{estimate[k] - nominal:+.3f}</td><td>{sigma}</td>"
        if true_vector is not None:
            error = true_vector[k] - estimate[k]
            cells += f"<td>{error:+.3f}</td><td>{error / std[k] if 0 < std[k] < np.inf else float('nan'):+.2f}</td>"
        rows.append(f"<tr><th class='l'>{name}</th>{cells}</tr>")
    return ("<p>mm; scale errors in mm per metre of reading.</p><table><tr><th class='l'>parameter</th><th>nominal</th>"
            f"<th>identified</th><th>deviation</th><th>σ</th>{extra}</tr>{''.join(rows)}</table>")


def _observability(result: IdentificationResult) -> str:
    o = result.observability
    return (f"<p>Condition number {o.condition_number:.3g}; smallest singular value {o.singular_values[-1]:.3g} /mm, i.e. the "
            f"worst-determined combination {_e(o.worst_direction_terms(result.parameters.has_scales))} is known to "
            f"±{o.worst_std_mm:.3g} mm (1σ). Rank {o.rank} of {len(o.singular_values)}.</p>")


def _img(png: bytes) -> str:
    return f"<img src='data:image/png;base64,{base64.b64encode(png).decode('ascii')}'>"


def _e(text: str) -> str:
    return html.escape(text)
