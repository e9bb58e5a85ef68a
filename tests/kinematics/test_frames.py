"""Work and tool frames: the transforms against numpy, round trips, and the pivot point."""

from math import radians

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hexactl.kinematics.frames import (
    IDENTITY,
    Frames,
    apply,
    compose,
    inverse,
    platform_poses,
    pose_of,
    tools_in_work,
    transform_of,
)
from hexactl.kinematics.rotation import rotation_matrix

mm = st.floats(-1000.0, 1000.0)
angle = st.floats(radians(-170.0), radians(170.0))
pitch = st.floats(radians(-80.0), radians(80.0))
poses = st.tuples(mm, mm, mm, angle, pitch, angle)


def _matrix(pose) -> np.ndarray:
    """4×4 homogeneous matrix of a pose, built with numpy (the oracle)."""
    m = np.eye(4)
    m[:3, :3] = rotation_matrix(*pose[3:])
    m[:3, 3] = pose[:3]
    return m


def _matrix_of(transform) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = np.reshape(transform.rotation, (3, 3))
    m[:3, 3] = transform.translation
    return m


@given(poses)
def test_a_pose_survives_the_round_trip_through_its_transform(pose):
    assert pose_of(transform_of(pose)) == pytest.approx(pose, abs=1e-9)


@given(poses, poses, st.tuples(mm, mm, mm))
def test_compose_inverse_and_apply_equal_the_matrix_products(a, b, point):
    ta, tb = transform_of(a), transform_of(b)
    assert _matrix_of(compose(ta, tb)) == pytest.approx(_matrix(a) @ _matrix(b), abs=1e-9)
    assert _matrix_of(inverse(ta)) == pytest.approx(np.linalg.inv(_matrix(a)), abs=1e-9)
    assert apply(ta, point) == pytest.approx((_matrix(a) @ [*point, 1.0])[:3], abs=1e-9)


@given(poses, poses, poses)
def test_the_tool_pose_in_the_work_frame_and_the_platform_pose_are_inverse_maps(work, tool, tool_in_work):
    frames = Frames(transform_of(work), transform_of(tool))
    platform = frames.platform_pose(tool_in_work)
    assert _matrix(platform) @ _matrix(tool) == pytest.approx(_matrix(work) @ _matrix(tool_in_work), abs=1e-6)
    assert _matrix(frames.tool_in_work(platform)) == pytest.approx(_matrix(tool_in_work), abs=1e-6)


@given(poses, poses, st.tuples(mm, mm, mm), st.lists(st.tuples(angle, pitch, angle), min_size=1, max_size=5))
def test_rotations_of_the_tool_pose_turn_the_platform_about_the_tool_point(work, tool, position, orientations):
    """The pivot point: whatever the orientation commanded, the tool frame's origin stays
    where the position puts it in the fixed frame."""
    frames = Frames(transform_of(work), transform_of(tool))
    pivot = apply(frames.work, position)
    for orientation in orientations:
        platform = frames.platform_pose((*position, *orientation))
        assert apply(transform_of(platform), frames.tool.translation) == pytest.approx(pivot, abs=1e-6)


@given(poses)
def test_identity_frames_leave_the_pose_as_it_is(pose):
    assert Frames().platform_pose(pose) == pytest.approx(pose, abs=1e-9)
    assert Frames(IDENTITY, IDENTITY).tool_in_work(pose) == pytest.approx(pose, abs=1e-9)


@given(poses, poses, st.lists(poses, min_size=1, max_size=10))
def test_the_batch_maps_equal_the_single_pose_ones(work, tool, samples):
    frames = Frames(transform_of(work), transform_of(tool))
    platform = platform_poses(frames, np.array(samples))
    assert platform == pytest.approx(np.array([frames.platform_pose(x) for x in samples]), abs=1e-6)
    assert tools_in_work(frames, platform) == pytest.approx(np.array([frames.tool_in_work(p) for p in platform]), abs=1e-6)


def test_a_tool_at_pitch_90_degrees_in_the_work_frame_is_read_there():
    # A work frame pitched -96° (a tool facing sideways), the platform pitched -6°: the
    # product's -sin(pitch) rounds to -(1 + 2⁻⁵²), which asin alone refuses.
    work_pitch = 1.6758680230392085
    frames = Frames(work=transform_of((0.0, 0.0, 0.0, 0.0, -work_pitch, 0.0)))
    platform = (0.0, 0.0, 2000.0, 0.0, np.pi / 2 - work_pitch, 0.0)
    assert frames.tool_in_work(platform)[4] == np.pi / 2
    assert tools_in_work(frames, np.array([platform]))[0, 4] == pytest.approx(np.pi / 2)
