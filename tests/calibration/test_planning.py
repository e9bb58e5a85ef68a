"""Leg-lock planning: the lock holds, every limit is kept with margin, postures are spread."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.calibration.planning import PlanMargins, PlanRequest, PlanStatus, plan_postures
from hexactl.kinematics.inverse import leg_lengths_batch
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.workspace import assess_poses


@pytest.mark.parametrize("leg", [1, 4, 6])
def test_leglock_plan_keeps_the_lock_and_the_limits(nominal, leg):
    plan = plan_postures(nominal, PlanRequest(leg=leg, count=12, candidates=300, seed=leg))
    assert plan.ok, plan.message
    lengths = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, plan.poses_relative))
    home_length = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, np.zeros((1, 6))))[0, leg - 1]
    assert plan.locked_length_mm == pytest.approx(home_length, abs=1e-9)
    assert np.max(np.abs(lengths[:, leg - 1] - plan.locked_length_mm)) < 1e-6
    assert np.allclose(plan.setpoints_mm[:, leg - 1], plan.locked_reading_mm, atol=1e-6)
    margins = PlanMargins()
    for assessment in assess_poses(nominal, plan.poses_relative):
        assert assessment.ok, assessment.violations
        assert margins.accepts(nominal, assessment)
    # D-optimal choice spreads the postures: every pose axis is exercised.
    assert np.all(np.ptp(plan.poses_relative, axis=0) > 0.2 * (np.array(nominal.limits.pose_max) - np.array(nominal.limits.pose_min)))


def test_locked_length_can_be_chosen(nominal):
    home_length = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, np.zeros((1, 6))))[0, 2]
    plan = plan_postures(nominal, PlanRequest(leg=3, count=8, candidates=300, locked_length_mm=home_length + 40.0))
    assert plan.ok, plan.message
    lengths = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, plan.poses_relative))
    assert np.max(np.abs(lengths[:, 2] - home_length - 40.0)) < 1e-6


def test_free_plan_and_bad_requests(nominal):
    free = plan_postures(nominal, PlanRequest(leg=0, count=10, candidates=200))
    assert free.ok and free.poses_relative.shape == (10, 6) and np.isnan(free.locked_length_mm)
    assert plan_postures(nominal, PlanRequest(leg=7, count=10)).status is PlanStatus.INVALID_REQUEST
    assert plan_postures(nominal, PlanRequest(leg=1, count=0)).status is PlanStatus.INVALID_REQUEST
    too_few = plan_postures(nominal, PlanRequest(leg=1, count=50, candidates=40))
    assert too_few.status is PlanStatus.INVALID_REQUEST
    assert too_few.message == ("40 candidates cannot give 50 postures: give at least 50 candidates "
                               "(more give a better-conditioned plan)")  # that one problem, and what to do
    # a candidate array beyond memory: numpy's "Maximum allowed dimension exceeded" traceback
    assert plan_postures(nominal, PlanRequest(leg=1, count=10, candidates=10**23)).status is PlanStatus.INVALID_REQUEST
    impossible = plan_postures(nominal, PlanRequest(leg=1, count=10, candidates=50, locked_length_mm=10_000.0))
    assert impossible.status is PlanStatus.TOO_FEW_FEASIBLE and "feasible" in impossible.message
