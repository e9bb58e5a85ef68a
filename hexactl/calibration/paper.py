"""``paper``: the paper's algorithm, kept to compare against (section 2 and 3.2).

Per leg, unknowns x = (P_mi, B_i); f_j = ‖T^j·P_mi + R^j − B_i‖² over the leg's locked
postures. Gauss–Newton on the consecutive differences h_j = f_j − f_{j+1} of an ordering
of the postures (equations 9–14, generalised inverse by least squares), each step scaled
down by a descending factor until the modified objective J = Σ(f_j − f_avg)² decreases
(3.2 a and c), otherwise the iteration ends; the result is clipped to nominal ± the
allowed deviation (3.2 d). Repeated for random reorderings of the postures (3.2 b; the
paper used 200 000, the default here is smaller and seeded); the ordering with the
smallest J wins. The length is the mean of √f_j (equation 8) and the zero length that
length minus the locked reading.

Its weaknesses are kept on purpose: squared lengths weight postures unequally and bias
the estimate, the measured poses are taken as exact, and nothing uses the free legs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from hexactl.calibration.data import MeasurementData
from hexactl.calibration.leglock import LockedLegData, leg_by_leg_result, leg_problems
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, Method
from hexactl.kinematics.geometry import Geometry

_DESCENT_HALVINGS = 12  # descending factor down to 2⁻¹² before an ordering's iteration ends
_RELATIVE_TOLERANCE = 1e-12  # e2 of the paper, relative to J


def identify_paper(data: MeasurementData, nominal: Geometry, options: IdentificationOptions) -> IdentificationResult:
    """The paper's method on the locked postures (module docstring); INSUFFICIENT_DATA as leglock."""
    reason = (f"paper: the paper's squared-length objective, Gauss–Newton with descending factor and "
              f"{options.paper_orderings} random reorderings per leg (for comparison)")
    problems = leg_problems(data, nominal, options, Method.PAPER, reason)
    if isinstance(problems, IdentificationResult):
        return problems
    rng = np.random.default_rng(options.seed)
    estimates, legs, iterations = [], [], 0
    for leg_data, low, high, x0 in problems:
        # Paper order (P, B); the shared layout is (B, P, zero).
        paper_low, paper_high = np.concatenate((low[3:6], low[0:3])), np.concatenate((high[3:6], high[0:3]))
        count = len(leg_data.rows)
        orderings = np.array([np.arange(count)] + [rng.permutation(count) for _ in range(max(options.paper_orderings - 1, 0))])
        solutions, objective, used = _gauss_newton(leg_data, np.concatenate((x0[3:6], x0[0:3])), orderings,
                                                   paper_low, paper_high, options.max_iterations)
        best = solutions[int(np.argmin(objective))]
        length = float(np.mean(np.sqrt(_squared_lengths(best[None, :], leg_data)[0])))
        estimates.append(np.concatenate((best[3:6], best[0:3], [length - float(np.mean(leg_data.readings))])))
        legs.append(leg_data)
        iterations = max(iterations, used)
    # The paper's iteration ends by its own rules (no decrease possible), which is its "converged".
    return leg_by_leg_result(Method.PAPER, reason, data, nominal, options, estimates, legs, iterations, True, [])


def _squared_lengths(x: NDArray, leg_data: LockedLegData) -> NDArray[np.float64]:
    """f (o, m) for o parameter vectors x = (P, B) (o, 6)."""
    vectors = np.einsum("mij,oj->omi", leg_data.rotations, x[:, 0:3]) + leg_data.translations - x[:, None, 3:6]
    return np.einsum("omi,omi->om", vectors, vectors)


def _objective(f: NDArray) -> NDArray[np.float64]:
    """The paper's modified objective J = Σ (f_j − f_avg)², per row of f (o, m)."""
    return np.sum((f - f.mean(axis=1, keepdims=True)) ** 2, axis=1)


def _gauss_newton(leg_data: LockedLegData, x0: NDArray, orderings: NDArray, low: NDArray, high: NDArray,
                  max_iterations: int) -> tuple[NDArray, NDArray, int]:
    """Run every ordering's iteration at once: (solutions (o, 6), J (o,), iterations used)."""
    x = np.repeat(x0[None, :], len(orderings), axis=0)
    f = _squared_lengths(x, leg_data)
    objective = _objective(f)
    active = np.ones(len(orderings), dtype=bool)
    iteration = 0
    for iteration in range(1, max_iterations + 1):
        vectors = np.einsum("mij,oj->omi", leg_data.rotations, x[:, 0:3]) + leg_data.translations - x[:, None, 3:6]
        gradient = np.concatenate((2.0 * np.einsum("mji,omj->omi", leg_data.rotations, vectors), -2.0 * vectors), axis=2)
        f_ordered = np.take_along_axis(f, orderings, axis=1)
        gradient_ordered = np.take_along_axis(gradient, orderings[:, :, None], axis=1)
        h = f_ordered[:, :-1] - f_ordered[:, 1:]
        jacobian = gradient_ordered[:, :-1] - gradient_ordered[:, 1:]
        normal = np.einsum("oki,okj->oij", jacobian, jacobian)
        step = -np.linalg.solve(normal, np.einsum("oki,ok->oi", jacobian, h)[:, :, None])[:, :, 0]
        factor = np.ones(len(orderings))
        improved = np.zeros(len(orderings), dtype=bool)
        for _ in range(_DESCENT_HALVINGS + 1):
            trial = np.clip(x + factor[:, None] * step, low, high)
            trial_f = _squared_lengths(trial, leg_data)
            trial_objective = _objective(trial_f)
            accept = active & ~improved & (trial_objective < objective)
            gain = objective - trial_objective
            x[accept], f[accept] = trial[accept], trial_f[accept]
            small = accept & (gain <= _RELATIVE_TOLERANCE * objective)
            objective[accept] = trial_objective[accept]
            active &= ~small
            improved |= accept
            factor[~improved] *= 0.5
            if np.all(improved | ~active):
                break
        active &= improved  # no descending factor lowered J: this ordering's iteration ends
        if not np.any(active):
            break
    return x, objective, iteration
