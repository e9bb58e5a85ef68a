"""The calibration ramp alone: the offset between the set-points being sent and the new
geometry's fades out linearly, all legs together, at the configured share of the leg
velocity limit."""

from __future__ import annotations

from math import ceil

import pytest

from hexactl.control.calibration_ramp import CalibrationRamp
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.inverse import sensor_setpoints

PERIOD_S = 0.002
FRACTION = 0.1
POSE = (5.0, -3.0, 2.0, 0.01, 0.0, -0.02)  # relative mm/rad
OFFSET = (0.0, 1.0, -2.0, 0.5, 0.0, 0.25)  # mm: leg 3 moves most


@pytest.fixture
def active(geometry) -> ActiveGeometry:
    return ActiveGeometry.of(geometry, "new")


def ramp_from_offset(active: ActiveGeometry) -> tuple[CalibrationRamp, list[float]]:
    target = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad(POSE))
    ramp = CalibrationRamp(FRACTION, PERIOD_S)
    ramp.begin([t + o for t, o in zip(target, OFFSET)], active, POSE)
    return ramp, target


def test_it_starts_from_the_setpoints_being_sent_and_ends_on_the_new_ones(active):
    ramp, target = ramp_from_offset(active)
    assert ramp.active
    first = ramp.apply(list(target))
    assert first == pytest.approx([t + o for t, o in zip(target, OFFSET)], abs=1e-9)
    step_mm = FRACTION * active.geometry.limits.leg_velocity_mm_s * PERIOD_S
    expected_cycles = ceil(2.0 / step_mm)
    for _ in range(expected_cycles - 1):
        assert ramp.active
        previous, first = first, ramp.apply(list(target))
        changes = [n - p for n, p in zip(first, previous)]
        # all legs together: each by its share of the offset; the largest at the ramp's speed
        assert changes == pytest.approx([-o / 2.0 * step_mm for o in OFFSET], abs=1e-9)
    assert not ramp.active
    assert ramp.apply(list(target)) == target  # over: the new geometry's set-points as they are


def test_no_difference_no_ramp_and_it_ends_one_under_way(active):
    ramp, target = ramp_from_offset(active)
    ramp.begin(target, active, POSE)  # sent already equal to the new set-points
    assert not ramp.active
    desired = [1.0] * 6
    assert ramp.apply(desired) is desired


def test_a_new_swap_ramps_from_what_is_sent_and_cancel_forgets(active):
    ramp, target = ramp_from_offset(active)
    halfway = ramp.apply(list(target))
    ramp.begin([h + 1.0 for h in halfway], active, POSE)
    assert ramp.apply(list(target)) == pytest.approx([t + o + 1.0 for t, o in zip(target, OFFSET)], abs=1e-9)
    ramp.cancel()
    assert not ramp.active and ramp.apply(list(target)) == target
