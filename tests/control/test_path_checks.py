"""The path check's batch path: the first violation of each kind per waypoint, found from
the limits as arrays (building only the poses that can add one), is the one found pose by
pose from every pose's assessment, however the poses are cut into batches."""

from __future__ import annotations

from unittest import mock

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.control import planning
from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, PathViolation, PlanningBudget, PlanningContext
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.pose import pose_mm_deg_to_mm_rad
from hexactl.kinematics.workspace import assess_poses
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
