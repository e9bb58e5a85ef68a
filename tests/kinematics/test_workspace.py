from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.kinematics_commands import paper_extremes
from hexactl.kinematics import workspace
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import leg_jacobian_rows, reading_of_leg_length, sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_elements
from hexactl.kinematics.workspace import (
    PoseAssessment,
    ViolationKind,
    assess_pose,
    assess_poses,
    check_poses,
    jacobian_condition,
    pose_within_limits,
)
from tests.kinematics.strategies import relative_poses


def test_every_paper_stroke_extreme_is_reachable_on_the_nominal_geometry(nominal) -> None:
    assessments = assess_poses(nominal, paper_extremes())
    assert len(assessments) == 12
    for assessment in assessments:
        assert assessment.ok, [v.message for v in assessment.violations]
        assert min(assessment.stroke_margin_mm) > 0
        assert max(assessment.base_cone_deg) < nominal.limits.base_cone_deg
        assert max(assessment.platform_cone_deg) < nominal.limits.platform_cone_deg


def test_the_zero_posture_has_full_margins(nominal) -> None:
    home = assess_pose(nominal, [0.0] * 6)
    assert home.ok
    assert max(home.base_cone_deg) < 1e-6 and max(home.platform_cone_deg) < 1e-6


def test_all_violations_are_listed_at_once_with_legs_and_axes(nominal) -> None:
    far = assess_pose(nominal, [0.0, 0.0, 600.0, 0.0, 40.0, 0.0])
    kinds = {v.kind for v in far.violations}
    assert {ViolationKind.STROKE_HIGH, ViolationKind.POSE_RANGE} <= kinds
    assert {v.axis for v in far.violations if v.kind is ViolationKind.POSE_RANGE} == {"z", "pitch"}
    assert all(1 <= v.leg <= 6 for v in far.violations if v.kind is ViolationKind.STROKE_HIGH)
    assert any("above stroke" in v.message for v in far.violations)


def test_low_stroke_and_cone_limits_are_reported(nominal) -> None:
    low = assess_pose(nominal, [0.0, 0.0, -600.0, 0.0, 0.0, 0.0])
    assert all(v.kind in (ViolationKind.STROKE_LOW, ViolationKind.POSE_RANGE) for v in low.violations)
    assert sum(v.kind is ViolationKind.STROKE_LOW for v in low.violations) == 6
    tight = nominal.model_copy(
        update={"limits": nominal.limits.model_copy(update={"base_cone_deg": 20.0, "platform_cone_deg": 35.0})}
    )
    twisted = assess_pose(tight, [0.0, 0.0, 0.0, 0.0, 0.0, 60.0])  # cones 23.4° base, 39.8° platform
    for kind in (ViolationKind.BASE_CONE, ViolationKind.PLATFORM_CONE):
        cones = [v for v in twisted.violations if v.kind is kind]
        assert cones and all(v.value > v.limit for v in cones)


def test_margins_are_negative_exactly_where_limits_are_violated(nominal) -> None:
    for pose in ([0.0, 0.0, 300.0, 0.0, 0.0, 0.0], [700.0, 0.0, 0.0, 0.0, 0.0, 0.0]):
        assessment = assess_pose(nominal, pose)
        stroke_violated = any(v.kind in (ViolationKind.STROKE_LOW, ViolationKind.STROKE_HIGH) for v in assessment.violations)
        assert stroke_violated == (min(assessment.stroke_margin_mm) < 0)
        range_violated = any(v.kind is ViolationKind.POSE_RANGE for v in assessment.violations)
        assert range_violated == (min(assessment.pose_margin) < 0)


def test_the_envelopes_bounds_themselves_are_allowed(nominal) -> None:
    # A move to x = 610 was refused as "x 610 mm outside [-610, 610]": the trajectory's
    # samples overshoot the goal by an ulp (610.0000000000001).
    for axis, bound in ((0, 610.0), (1, -610.0), (5, 61.0)):
        pose = [0.0] * 6
        pose[axis] = bound
        pose[axis] = np.nextafter(bound, 2 * bound)
        assert not [v for v in assess_pose(nominal, pose).violations if v.kind is ViolationKind.POSE_RANGE]


def test_an_envelope_violation_says_by_how_much(nominal) -> None:
    (violation,) = assess_pose(nominal, [610.001, 0, 0, 0, 0, 0]).violations
    assert violation.message == "x 610.001 mm outside the pose envelope [-610, 610] mm (by 0.001 mm)"


VARIANTS = {
    "nominal": {},
    "short stroke": {"stroke": (50.0, 750.0)},
    "tight cones": {"base_cone_deg": 12.0, "platform_cone_deg": 20.0},
    "near-singular at 9": {"max_jacobian_condition": 9.0},
}
"""Limits changed from the nominal so that each kind binds inside the pose envelope."""


def variant(nominal: Geometry, name: str, gains: bool = False, **limits: object) -> Geometry:
    """The nominal geometry with the limits of :data:`VARIANTS` ``name`` and then
    ``limits``; with ``gains``, sensors with scale errors (the sensor model not the identity)."""
    fields = nominal.model_dump()
    fields["limits"] |= VARIANTS[name] | limits
    if gains:
        fields["sensor_scale_errors"] = (1e-2, -8e-3, 5e-3, 7e-3, -1e-2, 6e-3)
    return Geometry.model_validate(fields)


def margin(assessment: PoseAssessment, geometry: Geometry) -> float:
    """The smallest distance of any limit from being on its bound (mm, deg, or relative for
    the condition number)."""
    limits = geometry.limits
    return min(*np.abs(assessment.stroke_margin_mm), *np.abs(np.subtract(assessment.base_cone_deg, limits.base_cone_deg)),
               *np.abs(np.subtract(assessment.platform_cone_deg, limits.platform_cone_deg)), *np.abs(assessment.pose_margin),
               abs(assessment.jacobian_condition / limits.max_jacobian_condition - 1.0))


@settings(max_examples=400, deadline=None)
@given(pose=relative_poses(scale=1.2), name=st.sampled_from(sorted(VARIANTS)), gains=st.booleans())
def test_the_yes_no_check_says_what_the_full_assessment_says(nominal, pose, name, gains) -> None:
    geometry = variant(nominal, name, gains)
    assessment = assess_pose(geometry, pose)
    assume(margin(assessment, geometry) > 1e-6)  # on a bound, the two paths' rounding may differ
    assert pose_within_limits(geometry, pose) == assessment.ok, [v.message for v in assessment.violations]


def test_a_reading_on_the_stroke_is_inside_and_one_a_hair_beyond_is_not(nominal) -> None:
    # The guard sends a set-point on the stroke's end as it is; the stroke has no rounding
    # allowance (POSE_BOUND_ROUNDING): nothing past it passes either check.
    pose = [100.0, -50.0, 30.0, 2.0, -3.0, 5.0]
    batch = assess_pose(nominal, pose).sensor_mm
    scalar = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, pose))
    for readings, inside in ((batch, lambda geometry: assess_pose(geometry, pose).ok),
                             (scalar, lambda geometry: pose_within_limits(geometry, pose))):
        low, high = min(readings), max(readings)
        assert inside(variant(nominal, "nominal", stroke=(low, high)))
        assert not inside(variant(nominal, "nominal", stroke=(np.nextafter(low, np.inf), high)))
        assert not inside(variant(nominal, "nominal", stroke=(low, np.nextafter(high, -np.inf))))


def test_a_nan_condition_number_is_near_singular(nominal) -> None:
    assert workspace.near_singular(float("nan"), nominal.limits)
    assert workspace.near_singular(np.array([np.nan, 1.0]), nominal.limits).tolist() == [True, False]


@pytest.mark.parametrize("name, pose, kind, relaxed", [
    ("short stroke", [600.0, 0.0, 250.0, 0.0, 0.0, 0.0], ViolationKind.STROKE_HIGH, {"stroke": (50.0, 850.0)}),
    ("short stroke", [600.0, 0.0, -250.0, 0.0, 0.0, 0.0], ViolationKind.STROKE_LOW, {"stroke": (0.0, 750.0)}),
    ("nominal", [611.0, 0.0, 0.0, 0.0, 0.0, 0.0], ViolationKind.POSE_RANGE, {"pose_max": (620.0, 610.0, 255.0, 24.0, 24.0, 61.0)}),
    ("tight cones", [600.0, 0.0, -250.0, 0.0, 0.0, 0.0], ViolationKind.BASE_CONE, {"base_cone_deg": 30.0}),
    ("tight cones", [0.0, 0.0, 0.0, 20.0, 0.0, 0.0], ViolationKind.PLATFORM_CONE, {"platform_cone_deg": 45.0}),
    ("near-singular at 9", [0.0, 0.0, 0.0, 20.0, 0.0, 0.0], ViolationKind.SINGULAR, {"max_jacobian_condition": 60.0}),
])
def test_each_kind_of_limit_alone_makes_the_check_say_no(nominal, name, pose, kind, relaxed) -> None:
    geometry = variant(nominal, name)
    assert {v.kind for v in assess_pose(geometry, pose).violations} == {kind}
    assert not pose_within_limits(geometry, pose)
    assert pose_within_limits(variant(nominal, name, **relaxed), pose)


def test_the_stroke_is_checked_on_the_sensors_readings(nominal) -> None:
    pose = [600.0, 0.0, 250.0, 0.0, 0.0, 0.0]
    highest = max(assess_pose(variant(nominal, "nominal", gains=True), pose).sensor_mm)
    for bound, inside in ((highest + 0.5, True), (highest - 0.5, False)):  # the gains move readings by ≥ 3.5 mm here
        limited = variant(nominal, "nominal", gains=True, stroke=(0.0, bound))
        assert assess_pose(limited, pose).ok is inside
        assert pose_within_limits(limited, pose) is inside


def _angle_between_deg(a, b) -> float:
    cross = np.cross(a, b)
    return float(np.degrees(np.arctan2(np.linalg.norm(cross), np.dot(a, b))))


def _assessed_alone(geometry: Geometry, pose) -> dict:
    """What the limits say about one pose, pose by pose in plain floats (the twist
    Jacobian's rows of :func:`leg_jacobian_rows`, as the stream's check and the condition
    number one pose at a time): the reference for the batch."""
    limits = geometry.limits
    absolute = absolute_from_relative(geometry.home, pose)
    rows, lengths = leg_jacobian_rows(geometry.legs, absolute)
    home_rows, _ = leg_jacobian_rows(geometry.legs, absolute_from_relative(geometry.home, [0.0] * 6))
    rotation = np.reshape(rotation_elements(*absolute[3:]), (3, 3))
    home_rotation = np.reshape(rotation_elements(*np.radians(geometry.home[3:])), (3, 3))
    sensor = [reading_of_leg_length(geometry.legs, leg, length) for leg, length in enumerate(lengths)]
    base = [_angle_between_deg(row[:3], neutral[:3]) for row, neutral in zip(rows, home_rows)]
    platform = [_angle_between_deg(rotation.T @ row[:3], home_rotation.T @ neutral[:3]) for row, neutral in zip(rows, home_rows)]
    condition = jacobian_condition(geometry, absolute)
    broken = []
    for leg in range(6):
        if sensor[leg] < limits.stroke[0]:
            broken.append((ViolationKind.STROKE_LOW, leg + 1, None, limits.stroke[0], sensor[leg]))
        elif sensor[leg] > limits.stroke[1]:
            broken.append((ViolationKind.STROKE_HIGH, leg + 1, None, limits.stroke[1], sensor[leg]))
        if base[leg] > limits.base_cone_deg:
            broken.append((ViolationKind.BASE_CONE, leg + 1, None, limits.base_cone_deg, base[leg]))
        if platform[leg] > limits.platform_cone_deg:
            broken.append((ViolationKind.PLATFORM_CONE, leg + 1, None, limits.platform_cone_deg, platform[leg]))
    for axis, value, low, high in zip("x y z roll pitch yaw".split(), pose, limits.pose_min, limits.pose_max):
        if not low - 1e-9 <= value <= high + 1e-9:
            broken.append((ViolationKind.POSE_RANGE, None, axis, high if value > high else low, value))
    if not condition <= limits.max_jacobian_condition:
        broken.append((ViolationKind.SINGULAR, None, None, limits.max_jacobian_condition, condition))
    return {"sensor": sensor, "base": base, "platform": platform, "condition": condition, "broken": broken}


@settings(max_examples=150, deadline=None)
@given(poses=st.lists(relative_poses(scale=1.3), min_size=1, max_size=12), name=st.sampled_from(sorted(VARIANTS)),
       gains=st.booleans())
def test_the_batch_says_what_each_pose_alone_says(nominal, poses, name, gains) -> None:
    """The batch (one stacked SVD for the condition numbers, the limits as arrays, objects
    built from them) against each pose checked alone in plain floats, the reachable and the
    violating: the same figures, the same violations in the same order; and each pose's
    assessment in the batch is the one it gets alone."""
    geometry = variant(nominal, name, gains)
    batch = assess_poses(geometry, poses)
    checks = check_poses(geometry, poses)
    assert checks.ok.tolist() == [assessment.ok for assessment in batch]
    for pose, assessment in zip(poses, batch):
        alone = _assessed_alone(geometry, pose)
        assert assessment == assess_pose(geometry, pose)
        assert assessment.jacobian_condition == pytest.approx(alone["condition"], rel=1e-12)
        assert assessment.sensor_mm == pytest.approx(alone["sensor"], abs=1e-9)
        assert assessment.base_cone_deg == pytest.approx(alone["base"], abs=1e-7)
        assert assessment.platform_cone_deg == pytest.approx(alone["platform"], abs=1e-7)
        if margin(assessment, geometry) > 1e-6:  # on a bound, the two paths' rounding may differ
            assert [(v.kind, v.leg, v.axis, v.limit) for v in assessment.violations] == [b[:4] for b in alone["broken"]]
            assert [v.value for v in assessment.violations] == pytest.approx([b[4] for b in alone["broken"]], rel=1e-9)


@settings(max_examples=100, deadline=None)
@given(poses=st.lists(relative_poses(scale=1.5), min_size=1, max_size=30))
def test_the_batch_condition_number_is_each_poses_own(nominal, poses) -> None:
    absolute = absolute_from_relative(nominal.home, poses)
    batch = check_poses(nominal, poses).condition
    assert batch.tolist() == pytest.approx([jacobian_condition(nominal, pose) for pose in absolute], rel=1e-12)


def test_a_rank_deficient_jacobian_has_an_infinite_condition_number_in_the_batch(nominal) -> None:
    """A zero smallest singular value gives inf, without a division warning, beside a
    finite one (the identity scaled: the characteristic length)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        condition = workspace._conditions(nominal, np.stack((np.zeros((6, 6)), np.eye(6))))
    assert condition[0] == np.inf and condition[1] == pytest.approx(nominal.characteristic_length_mm, rel=1e-12)


@pytest.mark.parametrize(("value", "bound", "form", "text"), [
    (610.0001, 610.0, "g", "610.0001"), (-610.0000001, -610.0, "g", "-610.0000001"), (700.0, 610.0, "g", "700"),
    (850.0004, 850.0, ".3f", "850.0004"), (850.4, 850.0, ".3f", "850.400"),
    (850.0000004, 850.0, ".3f", "850.0000004"),  # found from outside: read "850" after a first fix
    (-0.0001, 0.0, ".3f", "-0.0001"),  # and "-0.000 mm < 0 mm"
    (5.0, 5.0, ".3f", "5.000"),
])
def test_a_value_beyond_its_bound_is_written_with_the_digits_that_tell_them_apart(value, bound, form, text) -> None:
    from hexactl.kinematics.workspace import _told_apart

    assert _told_apart(value, bound, form) == text

