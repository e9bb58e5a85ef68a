from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.kinematics_commands import paper_extremes
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import PoseAssessment, ViolationKind, assess_pose, assess_poses, pose_within_limits
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
