"""Identification options and results, shared by every method.

Every method ends in :func:`assemble_result`, so covariance, observability, outlier flags,
the noise-consistency test and the status follow one rule whatever produced the estimate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum, StrEnum

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.parameters import StructuralParameters
from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS
from hexactl.calibration.uncertainty import (
    DEFAULT_READING_SIGMA_MM,
    Observability,
    PredictedAccuracy,
    analyse_information,
    predict_accuracy,
)
from hexactl.kinematics.geometry import noise_sigma_problem


class Method(StrEnum):
    """Identification methods (see docs/calibration.md for when each applies)."""

    AUTO = "auto"  # full, unless the data show its model does not hold (then leglock)
    FULL = "full"  # all parameters from every posture and every reading, errors-in-variables ML
    LEGLOCK = "leglock"  # each leg from its locked postures alone, bounded least squares
    PAPER = "paper"  # the paper's squared-length objective with Gauss–Newton and reorderings


class IdentificationStatus(IntEnum):
    OK = 0
    WEAKLY_DETERMINED = 1  # solved, but the data leave commanded poses uncertain: see warnings
    NOT_CONVERGED = 2  # the iteration cap was reached: do not use the parameters
    NOT_OBSERVABLE = 3  # the data cannot determine some parameter combination at all
    INSUFFICIENT_DATA = 4  # too few postures for the method: nothing was identified
    IMPLAUSIBLE = 5  # beyond the nominal's plausibility bounds: not this machine, the data are wrong

    @property
    def text(self) -> str:
        """For people and files: ``weakly determined``."""
        return self.name.lower().replace("_", " ")


MIN_LOCKED_POSTURES = 8
"""Per leg, for leglock and paper: seven unknowns plus at least one redundant equation."""

MIN_POSTURES = 8
"""For full: each leg has seven unknowns and every posture gives one equation per leg."""

MIN_DEVIATION_BOUND_MM = 1e-3
"""A bound on a parameter's deviation from the nominal tighter than a micrometre pins it there:
nothing would be identified (and in floating point leglock's two bounds meet)."""


def deviation_bound_problem(bound_mm: float) -> str | None:
    """What is wrong with ``bound_mm`` as a bound on each parameter's deviation, mm; None if nothing."""
    if not MIN_DEVIATION_BOUND_MM <= bound_mm < float("inf"):
        return f"{bound_mm:g} is not a finite bound from {MIN_DEVIATION_BOUND_MM:g} mm on each parameter's deviation"
    return None


@dataclass(frozen=True, slots=True)
class IdentificationOptions:
    """Settings of an identification. Lengths in mm.

    ``point_sigma_mm`` None: the geometry's ``[measurement] point_sigma_mm``;
    ``reading_sigma_mm`` the sensors' noise. ``estimate_scales``: ``full`` also identifies
    the six sensor scale errors; ``estimate_drift``: and each leg's offset drift over the
    campaign (linear in the rows' order).
    ``max_joint_deviation_mm`` / ``max_zero_length_deviation_mm`` bound leglock's and
    paper's estimates around the nominal (the paper's boundary conditions).
    ``loss`` is leglock's scipy robust loss ("linear", "soft_l1", "huber", "cauchy",
    "arctan"), on residuals in noise standard deviations. ``paper_orderings`` random
    reorderings (seeded by ``seed``) for the paper's method (the paper used 200 000).
    ``max_predicted_position_mm`` / ``max_predicted_orientation_deg``: when the parameter
    uncertainty leaves the test motions' poses more uncertain than this (RMS, 1σ), the
    status is WEAKLY_DETERMINED. ``consistency_limit``: χ²/dof above it means the residuals
    do not match the noise model. ``outlier_probability``: a posture whose residual is
    less likely than this under the noise model is flagged. ``exclusion_false_alarm``: the
    probability that ``full`` excludes any observation of a campaign that has no
    gross error, mis-sighting or wrong reading (0 disables the exclusion).
    """

    method: Method = Method.AUTO
    point_sigma_mm: float | None = None
    reading_sigma_mm: float = DEFAULT_READING_SIGMA_MM
    estimate_scales: bool = False
    estimate_drift: bool = False
    max_joint_deviation_mm: float = 15.0
    max_zero_length_deviation_mm: float = 15.0
    loss: str = "linear"
    paper_orderings: int = 200
    seed: int = 0
    max_iterations: int = 100
    max_predicted_position_mm: float = 0.1
    max_predicted_orientation_deg: float = 0.01
    consistency_limit: float = 2.0
    outlier_probability: float = 1e-3
    exclusion_false_alarm: float = 0.01

    def __post_init__(self) -> None:
        """ValueError naming the setting whose noise or bound the identification cannot work with."""
        noises = {"reading_sigma_mm": self.reading_sigma_mm, "point_sigma_mm": self.point_sigma_mm}
        bounds = {"max_joint_deviation_mm": self.max_joint_deviation_mm,
                  "max_zero_length_deviation_mm": self.max_zero_length_deviation_mm}
        for name, value in noises.items():
            if value is not None and (problem := noise_sigma_problem(value)):
                raise ValueError(f"{name}: {problem}")
        for name, value in bounds.items():
            if problem := deviation_bound_problem(value):
                raise ValueError(f"{name}: {problem}")


@dataclass(frozen=True, slots=True, eq=False)
class PostureResiduals:
    """Per posture (N,): ``lines`` source lines; ``fit_rms_mm`` the residual a posture
    leaves, mm (full: feature points; leglock/paper: the locked leg's length); ``normalised``
    its χ² over its degrees of freedom (≈ 1 when it fits the noise model); ``outlier``
    when that is improbably large. Postures a method did not use have NaN and False."""

    lines: NDArray[np.int64]
    locked_leg: NDArray[np.int64]
    fit_rms_mm: NDArray[np.float64]
    normalised: NDArray[np.float64]
    outlier: NDArray[np.bool_]

    @property
    def outlier_lines(self) -> tuple[int, ...]:
        return tuple(int(line) for line in self.lines[self.outlier])


@dataclass(frozen=True, slots=True)
class ExcludedObservation:
    """An observation ``full`` left out as a gross error: a mis-sighting or a wrong reading.

    ``line`` its source line, ``row`` its index in the data. Which observation: ``leg`` the
    leg (1–6) whose sensor reading it is, else 0; ``point`` the feature point (1-based), else
    0; both 0 for a pose-form row's whole pose. ``residual_mm`` how far the final fit puts it
    from its measured value (pose form: the farthest implied feature point; a reading: the
    leg length the fit implies against the one the reading gives); ``sigmas`` its
    standardised residual (the Mahalanobis length, leverage included).
    """

    line: int
    row: int
    point: int
    residual_mm: float
    sigmas: float
    leg: int = 0

    @property
    def kind(self) -> str:
        """What its exclusion takes it for, for people: "mis-sighting" or "reading error"."""
        return "reading error" if self.leg else "mis-sighting"

    def __str__(self) -> str:
        what = f"leg {self.leg}'s reading" if self.leg else f"feature point p{self.point}" if self.point else "measured pose"
        return f"line {self.line}: {what} off by {self.residual_mm:.3f} mm ({self.sigmas:.1f} σ)"


def excluded_summary(excluded: tuple[ExcludedObservation, ...]) -> str:
    """How many observations of each kind ``full`` excluded, for people ("" for none)."""
    sightings = sum(1 for observation in excluded if not observation.leg)
    readings = len(excluded) - sightings
    counts = ([f"{sightings} mis-sighted observation(s)"] if sightings else []) + (
        [f"{readings} wrong reading(s)"] if readings else [])
    return f"{' and '.join(counts)} excluded" if counts else ""


@dataclass(frozen=True, slots=True, eq=False)
class Estimate:
    """Estimated values and their standard deviations, of one shape and unit."""

    value: NDArray[np.float64]
    std: NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class IdentificationResult:
    """What an identification found, and how far to trust it.

    ``covariance`` (p, p) of the parameter vector (mm²; scaled by χ²/dof when the residuals
    exceed the noise model, so standard deviations stay honest); ``residual_rms_mm`` and
    ``expected_rms_mm``: the fit residual and what the noise model predicts for it;
    ``predicted``: the pose error the parameter uncertainty alone leaves on the paper's
    test motions (the Cramér–Rao prediction when the method is ``full``);
    ``reason``: why this method (auto's choice explained); ``warnings``: for people;
    ``excluded``: the observations ``full`` left out as gross errors, mis-sightings and wrong
    readings (empty for the others);
    ``offset_drift_mm`` and ``feature_points_mm``: what ``full`` estimated besides the
    structural parameters, when it did (``covariance`` is the structural parameters'
    marginal: their uncertainty is in it).
    Use the parameters only when ``ok``.
    """

    status: IdentificationStatus
    method: Method
    reason: str
    parameters: StructuralParameters
    covariance: NDArray[np.float64]
    observability: Observability
    residuals: PostureResiduals
    residual_rms_mm: float
    expected_rms_mm: float
    chi2_per_dof: float
    predicted: PredictedAccuracy
    postures_used: int
    iterations: int
    warnings: tuple[str, ...]
    excluded: tuple[ExcludedObservation, ...] = ()
    degrees_of_freedom: int = 0  # of the χ² test (redundant observations)
    offset_drift_mm: Estimate | None = None  # (6,) zero length at the campaign's end minus at its start
    feature_points_mm: Estimate | None = None  # (K, 3) identified feature points, moving frame

    @property
    def chi2(self) -> float:
        """The fit's total χ² (NaN where there is no redundancy)."""
        return self.chi2_per_dof * self.degrees_of_freedom

    @property
    def ok(self) -> bool:
        return self.status in (IdentificationStatus.OK, IdentificationStatus.WEAKLY_DETERMINED)

    @property
    def consistency(self) -> str:
        """χ²/dof for people; NaN (nothing identified, or no redundant observation) says so."""
        if np.isfinite(self.chi2_per_dof):
            return f"χ²/dof {self.chi2_per_dof:.3f}"
        return "χ²/dof not available (no redundant observation to test the fit against the noise model)"

    @property
    def std_vector(self) -> NDArray[np.float64]:
        """Each parameter's standard deviation, in the parameter vector's order and units;
        infinite for a parameter the data do not determine (the covariance leaves its
        undetermined part out, and its diagonal alone would show a small σ)."""
        std = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        return np.where(self.observability.undetermined, np.inf, std)

    @property
    def std(self) -> StructuralParameters:
        """:attr:`std_vector`, shaped like the parameters (mm; scale errors dimensionless)."""
        return StructuralParameters.from_vector(self.std_vector, self.parameters.has_scales)


LINES_NAMED = 12
"""Lines a note names at most: past a dozen, a list of line numbers is noise (every line of a
file measured in another frame); the count says how many."""


def assemble_result(
    method: Method,
    reason: str,
    parameters: StructuralParameters,
    information: NDArray,
    residuals: PostureResiduals,
    chi2_total: float,
    degrees_of_freedom: int,
    residual_rms_mm: float,
    expected_rms_mm: float,
    iterations: int,
    converged: bool,
    options: IdentificationOptions,
    home_mm_deg: tuple[float, ...],
    warnings: tuple[str, ...] = (),
    excluded: tuple[ExcludedObservation, ...] = (),
    covariance: NDArray | None = None,
) -> IdentificationResult:
    """Covariance, observability, χ² test, predicted accuracy and status from a method's
    raw outcome; ``home_mm_deg`` is the zero posture the test motions are relative to.
    ``covariance``: the parameters' with the residuals' excess noise in it (full's, per
    observation group); None: ``information``'s inverse, scaled up by χ²/dof above 1."""
    # Without redundant observations the residuals are zero by construction: no test.
    chi2_per_dof = chi2_total / degrees_of_freedom if degrees_of_freedom > 0 else float("nan")
    modelled, observability = analyse_information(information)  # what the postures determine: the noise model's
    excess = chi2_per_dof if chi2_per_dof > 1.0 else 1.0  # the noise is larger than its model says
    if covariance is None:  # every σ scaled up alike
        covariance = modelled * excess
    direction = observability.worst_direction
    observability = replace(observability, worst_std_mm=float(np.sqrt(direction @ covariance @ direction))
                            if observability.full_rank else observability.worst_std_mm * np.sqrt(excess))
    notes = list(warnings)
    if chi2_per_dof > options.consistency_limit:
        notes.append(
            f"residuals are {np.sqrt(chi2_per_dof):.2g}× the noise model (χ²/dof {chi2_per_dof:.3g}): the noise "
            "figures are optimistic (the instrument's point_sigma_mm, --point-sigma) or something is not modelled "
            "(outliers, joint play, drift); standard deviations are scaled up accordingly")
    elif noise := noise_model_note(chi2_total, degrees_of_freedom, len(excluded)):
        notes.append(noise)
    outliers = residuals.outlier_lines
    if outliers:
        shown = ", ".join(map(str, outliers[:LINES_NAMED])) + (
            f" and {len(outliers) - LINES_NAMED} more" if len(outliers) > LINES_NAMED else "")
        notes.append(f"{len(outliers)} posture(s) fit worse than the noise model allows (p < "
                     f"{options.outlier_probability:g}): lines {shown}")
    with_scales = parameters.has_scales
    status = IdentificationStatus.OK
    # Undetermined parameters are the cause when both happen: say that first.
    if not observability.full_rank:
        status = IdentificationStatus.NOT_OBSERVABLE
        notes.append(f"the data cannot determine {len(observability.singular_values) - observability.rank} "
                     f"parameter combination(s), e.g. {observability.worst_direction_terms(with_scales)}: "
                     "add postures that move these joints differently")
    elif not converged:
        status = IdentificationStatus.NOT_CONVERGED
        notes.append(f"no convergence within {iterations} iterations: do not use these parameters")
    predicted = predict_accuracy(parameters.legs(), covariance, PAPER_TEST_MOTIONS, home_mm_deg)
    if status is IdentificationStatus.OK and (
        predicted.rms_position_mm > options.max_predicted_position_mm
        or predicted.rms_orientation_deg > options.max_predicted_orientation_deg
    ):
        status = IdentificationStatus.WEAKLY_DETERMINED
        notes.append(f"weakly determined: the parameter uncertainty alone leaves the test motions' poses uncertain "
                     f"by {predicted.rms_position_mm:.3g} mm and {predicted.rms_orientation_deg:.3g}° RMS per axis (limits "
                     f"{options.max_predicted_position_mm:g} mm, {options.max_predicted_orientation_deg:g}°); the worst "
                     f"combination {observability.worst_direction_terms(with_scales)} is known to "
                     f"±{observability.worst_std_mm:.3g} mm: add or spread postures")
    return IdentificationResult(status, method, reason, parameters, covariance, observability, residuals,
                                residual_rms_mm, expected_rms_mm, chi2_per_dof, predicted,
                                int(np.count_nonzero(np.isfinite(residuals.normalised))), iterations, tuple(notes),
                                excluded, degrees_of_freedom)


NOISE_TEST_FALSE_ALARM = 1e-3
"""The noise model's test (:func:`noise_model_note`): its probability of firing on data
whose noise is what the model says."""


def noise_model_note(chi2_total: float, degrees_of_freedom: int, excluded: int) -> str | None:
    """A note when the residuals' χ² lies where the noise model puts it with less than
    :data:`NOISE_TEST_FALSE_ALARM` probability, either side (None otherwise, and without
    degrees of freedom). χ²/dof is within ``consistency_limit`` here, but with hundreds of
    degrees of freedom 1.3 already says the noise figures are optimistic, and 0.7 that they
    are pessimistic: a fixed limit does not see it, and σ and the predicted accuracy follow
    the figures. ``excluded``: observations cut as gross errors, which were judged against
    the noise figures."""
    from scipy.stats import chi2  # imported here: see flag_outliers

    if degrees_of_freedom <= 0 or not np.isfinite(chi2_total):
        return None
    ratio = chi2_total / degrees_of_freedom
    chance = (f"χ²/dof {ratio:.3g}, which {degrees_of_freedom} degrees of freedom leave to chance with p < "
              f"{NOISE_TEST_FALSE_ALARM:g}")
    if chi2_total > chi2.isf(NOISE_TEST_FALSE_ALARM, degrees_of_freedom):
        cut = (f"; the {excluded} observation(s) excluded as gross errors were judged against these figures and may "
               "be ordinary: calibrate again with the noise figures raised to see" if excluded else "")
        return (f"residuals are {np.sqrt(ratio):.2g}× the noise model ({chance}): the noise figures look optimistic "
                f"(the instrument's point_sigma_mm, --point-sigma, --reading-sigma); standard deviations are scaled "
                f"up accordingly{cut}")
    if chi2_total < chi2.ppf(NOISE_TEST_FALSE_ALARM, degrees_of_freedom):
        return (f"residuals are {np.sqrt(ratio):.2g}× the noise model ({chance}): the noise figures are pessimistic, "
                "and so are the standard deviations and the predicted accuracy; give the instrument's noise "
                "(point_sigma_mm, --point-sigma, --reading-sigma) to have them honest (a figure is one σ for every "
                "axis: a tracker's noise, smaller across its beam than along it, is modelled axis by axis from its "
                "own observations, the tracker form with --instrument)")
    return None


def flag_outliers(chi2_values: NDArray, dof: NDArray | float, probability: float) -> NDArray[np.bool_]:
    """True where χ² with ``dof`` degrees of freedom is less likely than ``probability``."""
    # Imported here: scipy.stats takes most of a second to import, and every hexactl
    # process (the service's, each CLI command's) imports this module.
    from scipy.stats import chi2

    values = np.asarray(chi2_values, dtype=float)
    flagged = np.zeros(values.shape, dtype=bool)
    finite = np.isfinite(values)
    flagged[finite] = chi2.sf(values[finite], np.broadcast_to(dof, values.shape)[finite]) < probability
    return flagged


def failed_result(method: Method, reason: str, status: IdentificationStatus, nominal: StructuralParameters,
                  lines: NDArray, locked_leg: NDArray, message: str) -> IdentificationResult:
    """A result that identified nothing (nominal parameters, infinite uncertainty)."""
    size = nominal.size
    nan = np.full(len(lines), np.nan)
    observability = Observability(np.zeros(size), float("inf"), float("inf"), np.zeros(size), 0,
                                  np.ones(size, dtype=bool))
    residuals = PostureResiduals(np.asarray(lines), np.asarray(locked_leg), nan, nan, np.zeros(len(lines), dtype=bool))
    unknown = PredictedAccuracy(float("inf"), float("inf"), float("inf"), float("inf"))
    return IdentificationResult(status, method, reason, nominal, np.full((size, size), np.inf), observability,
                                residuals, float("nan"), float("nan"), float("nan"), unknown, 0, 0, (message,))

