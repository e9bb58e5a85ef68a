"""The calibration report's figures, as PNG bytes.

Figures are built on :class:`matplotlib.figure.Figure` directly and rendered by the Agg
canvas: no pyplot, so no global backend state and no display is ever needed.
"""

from __future__ import annotations

import io
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hexactl.calibration.parameters import PARAMETERS_PER_LEG
from hexactl.calibration.results import IdentificationResult
from hexactl.calibration.uncertainty import point_accuracy
from hexactl.calibration.validation import MotionResult
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.workspace import assess_poses

_LEG_COLOURS = ("#7f7f7f", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")  # index = locked leg


def _png(figure: Figure) -> bytes:
    FigureCanvasAgg(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    return buffer.getvalue()


def residuals_figure(result: IdentificationResult) -> bytes:
    """Per posture: the fit residual (mm) and its normalised χ², outliers marked."""
    residuals = result.residuals
    used = np.isfinite(residuals.normalised)
    index = np.arange(len(residuals.lines))[used]
    legs = residuals.locked_leg[used]
    figure = Figure(figsize=(10, 5.5))
    top, bottom = figure.subplots(2, 1, sharex=True)
    for leg in np.unique(legs):
        mask = legs == leg
        label = f"leg {leg} locked" if leg else "free"
        top.bar(index[mask], residuals.fit_rms_mm[used][mask], color=_LEG_COLOURS[leg], label=label, width=0.8)
        bottom.bar(index[mask], residuals.normalised[used][mask], color=_LEG_COLOURS[leg], width=0.8)
    top.axhline(result.expected_rms_mm, color="k", linestyle="--", linewidth=1, label="expected (noise model)")
    bottom.axhline(1.0, color="k", linestyle="--", linewidth=1)
    outliers = residuals.outlier[used]
    if np.any(outliers):
        bottom.plot(index[outliers], residuals.normalised[used][outliers], "rv", label="outlier")
        bottom.legend(loc="upper right", fontsize=8)
    top.set_ylabel("fit residual, mm")
    top.set_title(f"Residuals per posture ({result.method})")
    top.legend(loc="upper right", fontsize=8, ncol=4)
    bottom.set_ylabel("χ² / dof")
    bottom.set_xlabel("posture (file order)")
    return _png(figure)


def parameters_figure(result: IdentificationResult, nominal_vector: np.ndarray, true_vector: np.ndarray | None) -> bytes:
    """Deviation of every parameter from the nominal with ±2σ bars (and the truth when known)."""
    geometric = slice(0, 6 * PARAMETERS_PER_LEG)  # the gains, in another unit, are in the table only
    estimate, nominal_vector = result.parameters.to_vector()[geometric], nominal_vector[geometric]
    true_vector = None if true_vector is None else true_vector[geometric]
    std = result.std_vector[geometric]
    deviation = estimate - nominal_vector
    figure = Figure(figsize=(10, 7))
    axes = figure.subplots(3, 1)
    groups = (("base joints B_i", slice(0, 3), "xyz"), ("platform joints P_mi", slice(3, 6), "xyz"), ("zero lengths", slice(6, 7), " "))
    for ax, (title, columns, labels) in zip(axes, groups):
        index = np.array([PARAMETERS_PER_LEG * leg + c for leg in range(6) for c in range(columns.start, columns.stop)])
        x = np.arange(len(index))
        bars = np.where(np.isfinite(std[index]), 2 * std[index], np.nan)  # no bar where undetermined
        ax.errorbar(x, deviation[index], yerr=bars, fmt="o", color="#1f77b4", ms=4, capsize=2,
                    label="identified − nominal (±2σ; none: not determined)")
        if true_vector is not None:
            ax.plot(x, true_vector[index] - nominal_vector[index], "x", color="#d62728", label="true − nominal")
        ax.axhline(0, color="k", linewidth=0.6)
        names = [f"{leg + 1}{labels[c - columns.start]}".strip() for leg in range(6) for c in range(columns.start, columns.stop)]
        ax.set_xticks(x, names, fontsize=7)
        ax.set_ylabel("mm")
        ax.set_title(title, fontsize=10)
    axes[0].legend(fontsize=8, loc="upper right")
    figure.tight_layout()
    return _png(figure)


def observability_figure(result: IdentificationResult) -> bytes:
    """Singular values of the whitened Jacobian and the parameter correlation matrix."""
    figure = Figure(figsize=(10, 4.2))
    left, right = figure.subplots(1, 2)
    singular = np.asarray(result.observability.singular_values)
    determined = singular > 0  # an undetermined combination's 0 has no place on a log axis
    if determined.any():
        left.semilogy(np.arange(1, len(singular) + 1)[determined], singular[determined], "o-", ms=3)
    if not determined.all():
        left.text(0.5, 0.5, f"{int(np.sum(~determined))} combination(s) not determined (0)", transform=left.transAxes,
                  ha="center", fontsize=9)
    left.set_xlabel("index")
    left.set_ylabel("singular value, 1/mm")
    left.set_title(f"Observability (condition {result.observability.condition_number:.3g})", fontsize=10)
    left.grid(True, which="both", alpha=0.3)
    std = np.sqrt(np.clip(np.diag(result.covariance), 0, None))
    scale = np.where((std > 0) & np.isfinite(std), std, 1.0)
    with np.errstate(invalid="ignore"):  # an undetermined parameter's ∞ leaves its row blank (NaN)
        correlations = np.where(np.isfinite(result.covariance), result.covariance, np.nan) / np.outer(scale, scale)
    image = right.imshow(correlations, vmin=-1, vmax=1, cmap="RdBu_r")
    right.set_title("parameter correlations (B, P, zero per leg)", fontsize=10)
    ticks = np.arange(0, len(std), PARAMETERS_PER_LEG)
    right.set_xticks(ticks, [f"leg {k + 1}" for k in range(len(ticks))], fontsize=7, rotation=45)
    right.set_yticks(ticks, [f"leg {k + 1}" for k in range(len(ticks))], fontsize=7)
    figure.colorbar(image, ax=right, shrink=0.8)
    return _png(figure)


def motion_figure(before: MotionResult, after: MotionResult) -> bytes:
    """Every pose axis' error against the swept command: before calibration on the top row,
    after on the bottom row, each on its own scale (the paper's Fig. 3/4 (a) and (b))."""
    motion = before.motion
    axis = motion.axis if motion.axis is not None else 0
    command = before.commanded_relative[:, axis]
    figure = Figure(figsize=(15, 5.5))
    grid = figure.subplots(2, 6)
    for row, (result, label, colour, marker) in enumerate(
        ((before, "before calibration", "#d62728", "o"), (after, "after calibration", "#2ca02c", "s"))
    ):
        for k, ax in enumerate(grid[row]):
            ax.plot(command, result.errors[:, k], marker + "-", color=colour, ms=4)
            ax.axhline(0, color="k", linewidth=0.6)
            ax.set_title(f"{POSE_AXES[k]} error, {POSE_UNITS[k]}", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(True, alpha=0.3)
            if row == 1:
                ax.set_xlabel(f"commanded {POSE_AXES[axis]}, {POSE_UNITS[axis]}", fontsize=8)
        grid[row][0].set_ylabel(label, fontsize=9, color=colour)
    figure.suptitle(f"{motion.title}: achieved − commanded")
    figure.tight_layout()
    return _png(figure)


ACCURACY_MAP_STEPS = 41
"""Grid points per axis of the accuracy maps."""


def accuracy_map_figure(result: IdentificationResult, nominal: Geometry) -> bytes:
    """The predicted 1σ position error of the platform's origin over the workspace: an
    x–y map at the zero posture's height and orientation, and a roll–pitch map at the zero
    posture's position; poses outside the limits left blank."""
    legs = result.parameters.legs()
    low, high = np.array(nominal.limits.pose_min), np.array(nominal.limits.pose_max)
    figure = Figure(figsize=(12, 4.8), layout="constrained")
    panels = figure.subplots(1, 2)
    for panel, (first, second) in zip(panels, ((0, 1), (3, 4))):
        a = np.linspace(low[first], high[first], ACCURACY_MAP_STEPS)
        b = np.linspace(low[second], high[second], ACCURACY_MAP_STEPS)
        grid = np.zeros((ACCURACY_MAP_STEPS * ACCURACY_MAP_STEPS, 6))
        grid[:, first], grid[:, second] = np.repeat(a, len(b)), np.tile(b, len(a))
        reachable = np.array([assessment.ok for assessment in assess_poses(nominal, grid)])
        sigma = np.full(len(grid), np.nan)
        for n in np.flatnonzero(reachable):
            sigma[n] = point_accuracy(legs, result.covariance, absolute_from_relative(nominal.home, grid[n])).position_mm
        image = panel.pcolormesh(a, b, sigma.reshape(len(a), len(b)).T, shading="nearest", cmap="viridis")
        figure.colorbar(image, ax=panel, label="predicted position error, radius √(σx²+σy²+σz²), mm (1σ)")
        panel.set_xlabel(f"{POSE_AXES[first]} ({POSE_UNITS[first]})")
        panel.set_ylabel(f"{POSE_AXES[second]} ({POSE_UNITS[second]})")
        panel.set_title(f"{POSE_AXES[first]}–{POSE_AXES[second]}, other axes at the zero posture")
    figure.suptitle("Predicted accuracy over the workspace, from the calibration's covariance")
    return _png(figure)
