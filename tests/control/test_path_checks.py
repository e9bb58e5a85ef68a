"""The path check's batch path: the first violation of each kind per waypoint, found from
the limits as arrays (building only the poses that can add one), is the one found pose by
pose from every pose's assessment, however the poses are cut into batches."""

from __future__ import annotations

from dataclasses import replace
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.control import planning
from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, PathViolation, PlanningBudget, PlanningContext, Waypoint, plan_path
from hexactl.control.frames import Frame
from hexactl.control.jog import JogPlan
from hexactl.control.jog_planning import plan_jog
from hexactl.control.trajectory import KinematicState, preview
from hexactl.kinematics.axes import PerAxis, RelativeMmRad
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.pose import pose_mm_deg_to_mm_rad
from hexactl.kinematics.workspace import ViolationKind, assess_poses, check_poses
from tests.kinematics.strategies import relative_poses

LIMITS = {
    "nominal": {},
    "tight cones": {"base_cone_deg": 12.0, "platform_cone_deg": 20.0},
    "short stroke": {"stroke": (50.0, 750.0)},
    "near-singular at 9": {"max_jacobian_condition": 9.0},
}

paths = st.lists(st.lists(relative_poses(scale=1.3), min_size=1, max_size=10), min_size=1, max_size=6)


def _limited(geometry: Geometry, name: str) -> Geometry:
    return geometry.model_copy(update={"limits": geometry.limits.model_copy(update=LIMITS[name])})


def _poses_and_owners(waypoint_paths: list[list[list[float]]]) -> tuple[np.ndarray, np.ndarray]:
    poses = np.array([pose for path in waypoint_paths for pose in path], dtype=float)
    owners = np.concatenate([np.full(len(path), number) for number, path in enumerate(waypoint_paths, start=1)])
    return poses, owners


def _pose_by_pose(geometry: Geometry, poses: np.ndarray, owners: np.ndarray) -> dict[tuple, PathViolation]:
    """The first violation of each kind per leg or axis and waypoint, every pose assessed in turn."""
    found: dict[tuple, PathViolation] = {}
    for assessment, owner in zip(assess_poses(geometry, poses), owners.tolist()):
        for v in assessment.violations:
            found.setdefault((owner, v.kind, v.leg, v.axis), PathViolation(
                v.kind, v.value, v.limit, v.message, v.leg, v.axis, waypoint=owner, pose=assessment.pose_relative))
    return found


@settings(max_examples=150, deadline=None)
@given(waypoint_paths=paths, name=st.sampled_from(sorted(LIMITS)), batch=st.integers(1, 25))
def test_the_first_violations_are_those_found_pose_by_pose(geometry, waypoint_paths, name, batch) -> None:
    limited = _limited(geometry, name)
    poses, owners = _poses_and_owners(waypoint_paths)
    found: dict[tuple, PathViolation] = {}
    for begin in range(0, len(poses), batch):
        planning._note_first_violations(limited, poses[begin:begin + batch], owners[begin:begin + batch], found)
    assert list(found.items()) == list(_pose_by_pose(limited, poses, owners).items())


@settings(max_examples=40, deadline=None)
@given(path=st.lists(relative_poses(scale=1.3), min_size=2, max_size=40), name=st.sampled_from(sorted(LIMITS)),
       batch=st.integers(1, 16))
def test_a_long_paths_violations_do_not_depend_on_the_batch_size(geometry, path, name, batch) -> None:
    """:func:`~hexactl.control.planning.budgeted_path_violations` (a wave's check) in
    batches of ``batch`` poses says what :func:`~hexactl.control.planning.path_violations`
    says of the path in one go."""
    limited = _limited(geometry, name)
    config = ControllerConfig()
    context = PlanningContext(ActiveGeometry.of(limited, "test"), config.motion, config.loop.period_s,
                              limited.limits.leg_velocity_mm_s)
    relative = pose_mm_deg_to_mm_rad(np.array(path))
    with mock.patch.object(planning, "_CHECK_BATCH", batch):
        batched = planning.budgeted_path_violations(context, relative, 1, PlanningBudget(), "here", "nothing")
    assert batched == planning.path_violations(context, relative, 1)


@settings(max_examples=100, deadline=None)
@given(poses=st.lists(relative_poses(scale=1.5), min_size=1, max_size=20), name=st.sampled_from(sorted(LIMITS)))
def test_a_pose_is_beyond_a_limit_by_a_positive_excess_exactly_where_it_breaks_it(geometry, poses, name) -> None:
    checks = check_poses(_limited(geometry, name), poses)
    np.testing.assert_array_equal(checks.excess() > 0, checks.broken)


def _context(geometry: Geometry) -> PlanningContext:
    config = ControllerConfig()
    return PlanningContext(ActiveGeometry.of(geometry, "test"), config.motion, config.loop.period_s,
                           geometry.limits.leg_velocity_mm_s)


def _beyond_y(geometry: Geometry, mm: float) -> RelativeMmRad:
    """At rest ``mm`` beyond the envelope's +y bound, as a platform held on the bound may read."""
    return RelativeMmRad(0.0, geometry.limits.pose_max[1] + mm, 0.0, 0.0, 0.0, 0.0)


def test_a_platform_a_hair_beyond_a_limit_may_move_back_inside(geometry) -> None:
    """Held on the envelope's bound, disabled and enabled again, it held the pose its
    quantised readings gave, 0.75 µm beyond: every move was refused, the move home
    included, and jog said to move back inside first (found from outside, 3 a.m. style)."""
    start = KinematicState.at_rest(_beyond_y(geometry, 0.75e-3))
    plan = plan_path(_context(geometry), start, [Waypoint((0, 0, 0, 0, 0, 0))])
    assert plan.ok, plan.refusal
    assert plan_path(_context(geometry), start, [Waypoint((0, 0, 0, 0, 0, 0)), Waypoint((0, 100, 0, 0, 0, 0))]).ok


def test_a_move_from_beyond_a_limit_may_go_no_further_out(geometry) -> None:
    """Moving out at 50 mm/s when the move home is asked, it brakes further out first:
    refused, naming the limit, as any path beyond it is."""
    start = KinematicState(_beyond_y(geometry, 0.75e-3), PerAxis((0.0, 50.0, 0.0, 0.0, 0.0, 0.0)),
                           PerAxis((0.0,) * 6))
    plan = plan_path(_context(geometry), start, [Waypoint((0, 0, 0, 0, 0, 0))])
    assert not plan.ok and [(v.kind, v.axis) for v in plan.refusal.violations] == [(ViolationKind.POSE_RANGE, "y")]


def test_a_goal_beyond_a_limit_is_refused_even_from_beyond_it(geometry) -> None:
    start = KinematicState.at_rest(_beyond_y(geometry, 0.75e-3))
    plan = plan_path(_context(geometry), start, [Waypoint((0, geometry.limits.pose_max[1] + 0.5e-3, 0, 0, 0, 0))])
    assert not plan.ok and "outside the pose envelope" in plan.refusal.message


def test_only_the_limits_the_platform_starts_beyond_are_eased_and_only_for_the_first_move(geometry) -> None:
    """From a hair beyond +y, a move may not cross another limit, and a later waypoint of
    the sequence may not leave the envelope by that hair either."""
    start = KinematicState.at_rest(_beyond_y(geometry, 0.75e-3))
    far = geometry.limits.pose_max[0] + 5.0
    refused = plan_path(_context(geometry), start, [Waypoint((far, 0, 0, 0, 0, 0))])
    assert not refused.ok and "x " in refused.refusal.message
    on_the_bound = geometry.limits.pose_max[1]
    assert plan_path(_context(geometry), start, [Waypoint((0, 0, 0, 0, 0, 0)), Waypoint((0, on_the_bound, 0, 0, 0, 0))]).ok


def test_a_jog_from_a_hair_beyond_a_limit_goes_back_inside_and_not_further_out(geometry) -> None:
    """It was refused: "move back inside with a move before jogging"."""
    start = KinematicState.at_rest(_beyond_y(geometry, 0.75e-3))
    inward = plan_jog(_context(geometry), start, None, (0, -20, 0, 0, 0, 0), Frame.ZERO, 200_000_000)
    assert isinstance(inward, JogPlan), inward
    assert inward.segment.goal[1] < start.position[1] - 10.0
    outward = plan_jog(_context(geometry), start, None, (0, 20, 0, 0, 0, 0), Frame.ZERO, 200_000_000)
    assert not isinstance(outward, JogPlan) and outward.message.endswith("jog the other way, back inside"), outward
    assert "outside the pose envelope" in outward.message


def _moving_x(at_mm: float, speed_mm_s: float) -> KinematicState:
    return KinematicState(RelativeMmRad(at_mm, 0.0, 0.0, 0.0, 0.0, 0.0), PerAxis((speed_mm_s, 0.0, 0.0, 0.0, 0.0, 0.0)),
                          PerAxis((0.0,) * 6))


@pytest.mark.parametrize(("goal_x", "duration_s"), [(100.0, 10.0), (100.0, 30.0), (100.0, 500.0), (0.0, 50.0),
                                                     (-300.0, 20.0)])
def test_a_duration_from_a_motion_under_way_takes_the_platform_no_further_than_braking_would(
        geometry, goal_x: float, duration_s: float) -> None:
    """Found from outside: a 30 s move to x = 100 sent at x = 8 while moving +x at 10 % of
    the velocity limit went out to x = 405 (its limits divided by 27 000 in jerk braked
    the motion under way), and 100 to 600 s ones were refused with no reason. Now it goes
    no further than the move without a duration, or braking to rest at the limits."""
    context = _context(geometry)
    start = _moving_x(8.0, 0.1 * context.limits.in_mm_rad()[0][0])
    timed = plan_path(context, start, [Waypoint((goal_x, 0, 0, 0, 0, 0), duration_s)])
    untimed = plan_path(context, start, [Waypoint((goal_x, 0, 0, 0, 0, 0))])
    assert timed.ok and untimed.ok, (timed.refusal, untimed.refusal)
    (segment,), (natural,) = timed.segments, untimed.segments
    assert duration_s <= segment.duration_s <= duration_s * 1.01 + 0.1, segment.duration_s

    def farthest(planned) -> float:
        trajectory = preview(context.limits, context.period_s, start, planned.goal, planned.time_scale,
                             planned.velocity_scale)
        return max(trajectory.at_time(t)[0][0] for t in np.linspace(0.0, trajectory.duration, 2001))

    halt = preview(context.limits, context.period_s, start, None)
    braked = max(halt.at_time(t)[0][0] for t in np.linspace(0.0, halt.duration, 2001))
    assert farthest(segment) <= max(farthest(natural), braked, goal_x) + 1e-6


def test_a_move_under_way_slowed_for_the_legs_speed_keeps_its_brake(geometry) -> None:
    """A leg speed budget the move's cruise breaks: from a motion under way it is kept by
    a lower velocity limit, not by stretching the brake from the motion under way."""
    context = replace(_context(geometry), leg_speed_mm_s=20.0)
    start = _moving_x(8.0, 15.0)
    plan = plan_path(context, start, [Waypoint((100, 0, 0, 0, 0, 0))])
    assert plan.ok, plan.refusal
    (segment,) = plan.segments
    assert segment.time_scale == 1.0 and segment.velocity_scale < 1.0
    trajectory = preview(context.limits, context.period_s, start, segment.goal, 1.0, segment.velocity_scale)
    xs = [trajectory.at_time(t)[0][0] for t in np.linspace(0.0, trajectory.duration, 2001)]
    assert max(xs) <= 100.0 + 1e-6 and min(xs) >= 8.0 - 1e-6
