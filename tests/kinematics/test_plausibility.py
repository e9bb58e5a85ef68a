"""Plausibility of a calibration against the nominal geometry (hexactl issue 10, finding 4)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.plausibility import implausibilities
from hexactl.sim.true_platform import ManufacturingErrors, true_geometry

from .calibrations import implausible_calibrations
from .conftest import REPOSITORY

NOMINAL = load_geometry(REPOSITORY / "config" / "platform.toml")
LIMITS = NOMINAL.limits
JOINT, ZERO = LIMITS.calibration_joint_tolerance_mm, LIMITS.calibration_zero_length_tolerance_mm
HOME_MM, HOME_DEG = LIMITS.calibration_home_tolerance_mm, LIMITS.calibration_home_tolerance_deg
JUDGE_ERRORS = ManufacturingErrors(joint_sigma_mm=4 * 2.0, zero_length_sigma_mm=4 * 3.0)  # 4× the simulator's


def _perturbed(base: np.ndarray, platform: np.ndarray, zero: np.ndarray, home: np.ndarray) -> Geometry:
    data = NOMINAL.model_dump()
    data.update(base_joints=(np.array(NOMINAL.base_joints) + base).tolist(),
                platform_joints=(np.array(NOMINAL.platform_joints) + platform).tolist(),
                zero_lengths=(np.array(NOMINAL.zero_lengths) + zero).tolist(),
                home=(np.array(NOMINAL.home) + home).tolist())
    return Geometry.model_validate(data)


def _offsets(count: int, bound: float, norm: bool) -> st.SearchStrategy[np.ndarray]:
    """``count`` 3-vectors of length ≤ ``bound`` (``norm``) or numbers of size ≤ ``bound``."""
    unit = st.floats(-1.0, 1.0)
    if not norm:
        return st.lists(unit, min_size=count, max_size=count).map(lambda v: bound * np.array(v))
    vectors = st.lists(st.tuples(unit, unit, unit, st.floats(0.0, 1.0)), min_size=count, max_size=count)

    def scale(rows):
        out = []
        for x, y, z, length in rows:
            direction = np.array([x, y, z])
            size = np.linalg.norm(direction)
            out.append(direction / size * bound * length if size > 1e-9 else np.zeros(3))
        return np.array(out)
    return vectors.map(scale)


INSIDE = 1.0 - 1e-9  # nominal + offset − nominal rounds: stay that much inside each bound
WITHIN = st.tuples(_offsets(6, INSIDE * JOINT, True), _offsets(6, INSIDE * JOINT, True),
                   _offsets(6, INSIDE * ZERO, False), _offsets(1, INSIDE * HOME_MM, True),
                   _offsets(3, INSIDE * HOME_DEG, False))


@settings(max_examples=80, deadline=None)
@given(WITHIN)
def test_anything_within_every_bound_is_plausible(offsets) -> None:
    base, platform, zero, home_mm, home_deg = offsets
    calibration = _perturbed(base, platform, zero, np.concatenate([home_mm[0], home_deg]))
    assert implausibilities(calibration, NOMINAL) == []


PARAMETERS = [("base_joints", 6, JOINT), ("platform_joints", 6, JOINT), ("zero_lengths", 6, ZERO),
              ("home_mm", 1, HOME_MM), ("home_deg", 3, HOME_DEG)]


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(PARAMETERS), st.integers(0, 5), st.floats(1.001, 3.0), st.floats(-1.0, 1.0),
       st.sampled_from([0, 1, 2]))
def test_anything_beyond_a_single_bound_is_refused_naming_it(parameter, index, factor, sign, axis) -> None:
    key, count, bound = parameter
    index %= count
    offsets = {"base_joints": np.zeros((6, 3)), "platform_joints": np.zeros((6, 3)), "zero_lengths": np.zeros(6),
               "home": np.zeros(6)}
    excess = bound * factor * (1.0 if sign >= 0 else -1.0)
    if key in ("base_joints", "platform_joints"):
        offsets[key][index, axis] = excess
        named = f"{key}[{index}] (leg {index + 1})"
    elif key == "zero_lengths":
        offsets[key][index] = excess
        named = f"zero_lengths[{index}] (leg {index + 1})"
    elif key == "home_mm":
        offsets["home"][axis] = excess
        named = "home[0:3]"
    else:
        offsets["home"][3 + index] = excess
        named = f"home[{3 + index}]"
    calibration = _perturbed(offsets["base_joints"], offsets["platform_joints"], offsets["zero_lengths"], offsets["home"])
    (problem,) = implausibilities(calibration, NOMINAL)
    assert problem.startswith(named) and f"bound {bound:g}" in problem and "[limits] calibration_" in problem


def test_the_defaults_accept_platforms_with_four_times_the_simulated_manufacturing_errors() -> None:
    refused = [seed for seed in range(2000) if implausibilities(true_geometry(NOMINAL, seed, JUDGE_ERRORS), NOMINAL)]
    assert refused == []


@pytest.mark.parametrize("case", ["base joints +1 m", "platform joints +300 mm", "home moved"])
def test_the_findings_calibrations_are_refused_naming_the_parameter(case) -> None:
    calibration, parameter = implausible_calibrations(NOMINAL, [100.0, 0.0, 0.0, 0.0, 0.0, 0.0])[case]
    problems = implausibilities(calibration, NOMINAL)
    assert any(problem.startswith(parameter) for problem in problems), problems


def test_the_bounds_come_from_the_nominal_limits() -> None:
    calibration, _ = implausible_calibrations(NOMINAL, [0.0] * 6)["platform joints +300 mm"]
    wide = NOMINAL.model_copy(update={"limits": LIMITS.model_copy(update={"calibration_joint_tolerance_mm": 400.0,
                                                                          "calibration_zero_length_tolerance_mm": 400.0})})
    assert implausibilities(calibration, wide) == []
