"""The leg-lock projection: on the surface, and the closest such pose."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from hexactl.kinematics.leg_lock import ProjectionStatus, project_to_locked_leg
from hexactl.kinematics.inverse import leg_lengths
from hexactl.kinematics.pose import absolute_from_relative

fractions = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6)


@settings(max_examples=60, deadline=None)
@given(start=fractions, target=fractions, leg=st.integers(1, 6))
# Found by this test: a correction of 760 mm needed 51 plain iterations (the cap is 50),
# and one of 1.05 m (the leg 1056 mm shorter) crawled on past a thousand.
@example(start=[-1.0, 0.0, 0.0, 0.0, 0.0, -1.0], target=[0.0, 0.0, 0.0, 1.0, 1.0, 0.0], leg=1)
@example(start=[1.0, -0.5, 1.0, -1.0, -1.0, -1.0], target=[-1.0, 0.5, 0.0, -0.5, 0.0, 0.5], leg=3)
def test_projection_lands_on_the_locked_length_and_is_locally_closest(nominal, start, target, leg):
    low, high = np.array(nominal.limits.pose_min), np.array(nominal.limits.pose_max)
    middle, half = (low + high) / 2, (high - low) / 2
    pose = absolute_from_relative(nominal.home, middle + half * np.array(start))
    length = leg_lengths(nominal.legs, absolute_from_relative(nominal.home, middle + 0.5 * half * np.array(target)))[leg - 1]
    c = nominal.characteristic_length_mm

    result = project_to_locked_leg(nominal.legs, pose, leg, length, c)

    assert result.status is ProjectionStatus.OK
    assert abs(leg_lengths(nominal.legs, result.pose)[leg - 1] - length) <= 1e-9
    # Optimality: the correction is parallel to W⁻¹·∇l (no tangential component), so no
    # nearby pose on the surface is closer. Check against poses moved along the surface.
    weights = np.array([1.0] * 3 + [c * c] * 3)
    distance = np.sqrt(np.sum(weights * (np.subtract(result.pose, pose)) ** 2))
    assert abs(distance - result.correction) < 1e-6 * max(1.0, distance)
    rng = np.random.default_rng(leg)
    for _ in range(3):
        nudged = np.array(result.pose) + rng.normal(0, 1.0, 6) * np.array([1.0] * 3 + [1.0 / c] * 3)
        other = project_to_locked_leg(nominal.legs, nudged, leg, length, c)
        assert other.ok
        assert np.sqrt(np.sum(weights * (np.subtract(other.pose, pose)) ** 2)) >= distance - 1e-6


def test_projection_reports_invalid_input(nominal):
    home = absolute_from_relative(nominal.home, np.zeros(6))
    for leg, length in ((0, 2000.0), (7, 2000.0), (1, -5.0), (1, float("nan"))):
        assert project_to_locked_leg(nominal.legs, home, leg, length, 900.0).status is ProjectionStatus.INVALID_INPUT
