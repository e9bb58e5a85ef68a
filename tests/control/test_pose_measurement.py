"""The measured pose alone: forward kinematics of the feedback, warm-started, at its rate."""

from __future__ import annotations

import pytest

from hexactl.control.hardware import ActuatorFeedback, ActuatorState, FeedbackSnapshot
from hexactl.control.planning import ActiveGeometry
from hexactl.control.pose_measurement import PoseMeasurement
from hexactl.kinematics.inverse import sensor_setpoints

POSE = (12.0, -8.0, 5.0, 0.02, -0.01, 0.03)  # relative mm/rad


def feedback_at(active: ActiveGeometry, positions) -> FeedbackSnapshot:
    return FeedbackSnapshot(tuple(ActuatorFeedback(p, 0.0, ActuatorState.ENABLED, 0, (), 0.0, 0) for p in positions), 0)


@pytest.fixture
def active(geometry) -> ActiveGeometry:
    return ActiveGeometry.of(geometry, "nominal")


def test_it_finds_the_pose_the_legs_are_at(active):
    measurement = PoseMeasurement(5, 1e-6, 10)
    legs = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad(POSE))
    measurement.measure(1, feedback_at(active, legs), active, (0.0,) * 6)
    assert measurement.pose == pytest.approx(POSE, abs=1e-6)
    assert measurement.failures == 0 and measurement.cycle == 1


def test_it_runs_every_n_cycles_and_at_once_after_a_geometry_change(active):
    measurement = PoseMeasurement(5, 1e-6, 10)
    legs = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad(POSE))
    measurement.measure(10, feedback_at(active, legs), active, POSE)
    assert [c for c in range(10, 21) if measurement.due(c)] == list(range(15, 21))
    measurement.geometry_changed()
    assert measurement.due(11)


def test_a_failure_is_counted_and_forgets_the_pose(active):
    measurement = PoseMeasurement(1, 1e-6, 10)
    legs = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad(POSE))
    measurement.measure(1, feedback_at(active, legs), active, POSE)
    measurement.measure(2, feedback_at(active, [legs[0] + 5000.0, *legs[1:]]), active, POSE)  # no pose has these
    assert measurement.pose is None and measurement.failures == 1
    # and it starts again from the commanded pose, not from the lost solution
    measurement.measure(3, feedback_at(active, legs), active, POSE)
    assert measurement.pose == pytest.approx(POSE, abs=1e-6)


def test_from_a_start_far_off_it_starts_again_from_the_zero_posture(active):
    # Leg 1 read 5 mm below its stroke (a glitch) has a pose far out, which the commanded
    # pose follows while disabled; from there FK of the legs back at the zero posture does
    # not converge. It was stuck: pose unknown for good, enable refused until a restart.
    measurement = PoseMeasurement(1, 1e-6, 10)
    legs = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad((0.0,) * 6))
    measurement.measure(1, feedback_at(active, [active.stroke[0] - 5.0, *legs[1:]]), active, (0.0,) * 6)
    far = measurement.pose
    assert far is not None and max(abs(v) for v in far[:3]) > 100.0
    measurement.measure(2, feedback_at(active, legs), active, far)  # from its last solution
    assert measurement.pose == pytest.approx((0.0,) * 6, abs=1e-6)
    measurement.measure(3, feedback_at(active, [active.stroke[0] - 5.0, *legs[1:]]), active, (0.0,) * 6)
    measurement.measure(4, feedback_at(active, [float("nan")] * 6), active, far)
    measurement.measure(5, feedback_at(active, legs), active, far)  # from the commanded pose
    assert measurement.pose == pytest.approx((0.0,) * 6, abs=1e-6)
    assert measurement.failures == 0  # a start it had to leave is no failure, nor are readings not there


def test_legs_not_read_yet_leave_the_pose_unknown_and_count_no_failure(active):
    """Found from outside: every service started with fk_failures 2, the cycles before the
    actuators' first reports (the link reads NaN until then), which it counted as FK failures."""
    measurement = PoseMeasurement(1, 1e-6, 10)
    legs = sensor_setpoints(active.geometry.legs, active.absolute_from_relative_mm_rad(POSE))
    measurement.measure(1, feedback_at(active, [float("nan")] * 6), active, POSE)
    measurement.measure(2, feedback_at(active, [*legs[:5], float("nan")]), active, POSE)
    assert measurement.pose is None and measurement.failures == 0
    measurement.measure(3, feedback_at(active, legs), active, POSE)
    assert measurement.pose == pytest.approx(POSE, abs=1e-6) and measurement.failures == 0
