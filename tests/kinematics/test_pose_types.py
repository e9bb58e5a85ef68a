"""The pose types: one per convention, converting themselves, validated as six finite numbers."""

from __future__ import annotations

from math import radians

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import BaseModel, ConfigDict, ValidationError

from hexactl.adapters.api.wire import decode_request
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.control.planning import ActiveGeometry
from hexactl.control.trajectory import KinematicState
from hexactl.kinematics.axes import POSE_AXES, AbsoluteMmDeg, AbsoluteMmRad, RelativeMmDeg, RelativeMmRad

finite = st.floats(-1e4, 1e4, allow_nan=False)
six = st.tuples(finite, finite, finite, finite, finite, finite)
TYPES = (RelativeMmDeg, RelativeMmRad, AbsoluteMmDeg, AbsoluteMmRad)


class _Holder(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    pose: RelativeMmDeg


@given(six)
def test_degrees_and_radians_convert_both_ways_and_keep_the_translation(values):
    pose = RelativeMmDeg(*values)
    in_rad = pose.in_radians()
    assert type(in_rad) is RelativeMmRad and in_rad[:3] == pose[:3]
    assert in_rad.roll == radians(pose.roll) and in_rad.yaw == radians(pose.yaw)
    assert in_rad.in_degrees() == pytest.approx(pose, rel=1e-12, abs=1e-9)
    assert type(AbsoluteMmDeg(*values).in_radians()) is AbsoluteMmRad


ACTIVE = ActiveGeometry.of(load_geometry(default_config_path()), "nominal")


@given(six)
def test_the_active_geometry_converts_relative_and_absolute_both_ways(relative):
    active = ACTIVE
    absolute = active.absolute_from_relative_mm_rad(RelativeMmRad(*relative))
    assert type(absolute) is AbsoluteMmRad
    assert absolute == tuple(h + r for h, r in zip(active.home, relative))
    back = active.relative_from_absolute_mm_rad(absolute)
    assert type(back) is RelativeMmRad and back == pytest.approx(relative, abs=1e-9)


def test_each_convention_is_its_own_type_and_still_a_tuple():
    values = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    poses = [kind(*values) for kind in TYPES]
    assert all(isinstance(pose, tuple) and pose == values and pose._fields == POSE_AXES for pose in poses)
    for i, kind in enumerate(TYPES):
        assert [isinstance(pose, kind) for pose in poses] == [j == i for j in range(len(TYPES))]


def test_a_kinematic_state_at_rest_has_no_velocity_or_acceleration():
    state = KinematicState.at_rest(RelativeMmRad(1.0, 2.0, 3.0, 0.1, 0.2, 0.3))
    assert state.position == (1.0, 2.0, 3.0, 0.1, 0.2, 0.3)
    assert state.velocity == state.acceleration == (0.0,) * 6


@pytest.mark.parametrize("value, message", [
    ([1, 2, 3], "a pose is six numbers [x, y, z, roll, pitch, yaw], got 3"),
    ([1, 2, 3, 4, 5, 6, 7], "got 7"),
    ({"x": 1, "y": 2, "z": 3, "roll": 4, "pitch": 5, "yaw": 6}, "a pose is six numbers"),
    ("123456", "a pose is six numbers"),
    ([1, 2, 3, 4, 5, float("nan")], "finite number"),
    ([1, 2, 3, 4, 5, "6"], "valid number"),
    ([1, 2, 3, 4, 5, True], "valid number"),
])
def test_pydantic_refuses_what_is_not_six_finite_numbers_and_says_so(value, message):
    with pytest.raises(ValidationError) as error:
        _Holder(pose=value)
    assert message in str(error.value)


def test_an_api_request_hands_over_a_typed_pose():
    request = decode_request(b'{"v": 1, "id": 1, "cmd": "move", "pose": [10, 0, 0, 0, 0, 5]}')
    assert type(request.pose) is RelativeMmDeg and request.pose.yaw == 5.0
