"""The campaign's pure pieces: visiting order, leg-lock paths, achieved poses, the verdict."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.application.demo import DEMO_ENVELOPE_FRACTION, DEMO_MOTION, DEMO_POSTURES_PER_LEG
from hexactl.calibration.campaign import (
    CampaignDesign,
    LOCKED_CHORD_TOLERANCE_MM,
    achieved_pose,
    campaign_postures,
    improved,
    locked_path,
    plan_campaign,
    travel_order,
)
from hexactl.calibration.planning import PlanRequest, PlanStatus, plan_postures
from hexactl.calibration.test_motions import X_SWEEP
from hexactl.calibration.validation import MotionResult, ValidationSummary, largest_stroke_error
from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, LegLock, PlanningContext, Waypoint, plan_path
from hexactl.control.trajectory import KinematicState
from hexactl.kinematics.axes import RelativeMmDeg
from hexactl.kinematics.inverse import leg_lengths, leg_lengths_batch
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_matrix


@pytest.fixture(scope="module")
def plans(nominal):
    return plan_campaign(nominal, CampaignDesign(postures_per_leg=6, candidates=300, seed=2))


def test_travel_order_visits_each_pose_once_nearest_first(nominal) -> None:
    poses = np.array([[300.0, 0, 0, 0, 0, 0], [10.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 2.0], [290.0, 0, 0, 0, 0, 1.0]])
    order = travel_order(poses, nominal.characteristic_length_mm)
    # 2° of yaw at the 900 mm joint radius is 31 mm: farther than 10 mm of x.
    assert order == [1, 2, 3, 0]


def test_travel_order_shortens_the_tour(nominal, plans) -> None:
    weights = np.array([1.0] * 3 + [nominal.characteristic_length_mm * np.pi / 180] * 3)

    def tour(poses):
        path = np.vstack([np.zeros(6), poses]) * weights
        return np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))

    for plan in plans:
        ordered = plan.poses_relative[travel_order(plan.poses_relative, nominal.characteristic_length_mm)]
        assert tour(ordered) <= tour(plan.poses_relative)


def test_campaign_postures_go_leg_by_leg_and_keep_every_planned_pose(nominal, plans) -> None:
    postures = campaign_postures(plans, nominal.characteristic_length_mm)
    assert [p.leg for p in postures] == [leg for leg in range(1, 7) for _ in range(6)]
    for plan in plans:
        mine = sorted(map(tuple, np.round([p.pose for p in postures if p.leg == plan.leg], 9)))
        assert mine == sorted(map(tuple, np.round(plan.poses_relative, 9)))


def test_a_free_plan_is_not_a_campaign(nominal) -> None:
    free = plan_campaign(nominal, CampaignDesign(postures_per_leg=0, free_postures=3, candidates=50))
    with pytest.raises(ValueError, match="locks a leg"):
        campaign_postures(free, nominal.characteristic_length_mm)


def test_locked_path_keeps_every_chord_near_the_constraint(nominal, plans) -> None:
    plan = plans[2]
    start, goal = np.zeros(6), plan.poses_relative[0]
    for a, b in zip(plan.poses_relative[:-1], plan.poses_relative[1:]):  # the planner's order: long moves
        path = locked_path(nominal, plan.leg, plan.locked_length_mm, a, b)
        assert path[-1] == pytest.approx(tuple(b))
        previous = a
        for waypoint in path:
            assert leg_lengths(nominal.legs, absolute_from_relative(nominal.home, waypoint))[plan.leg - 1] == pytest.approx(
                plan.locked_length_mm, abs=1e-6)
            chord = previous + (np.array(waypoint) - previous) * np.linspace(0, 1, 50)[:, None]
            stray = leg_lengths_batch(nominal.legs, absolute_from_relative(nominal.home, chord))[:, plan.leg - 1]
            assert np.max(np.abs(stray - plan.locked_length_mm)) <= LOCKED_CHORD_TOLERANCE_MM * 1.05
            previous = np.array(waypoint)
    assert locked_path(nominal, plan.leg, plan.locked_length_mm, start, start) == [tuple(start)]
    assert len(locked_path(nominal, plan.leg, plan.locked_length_mm, start, goal, tolerance_mm=1e9)) == 1


def test_the_controller_refuses_some_unsplit_demo_moves_and_accepts_every_piece_of_locked_path(nominal) -> None:
    """Why a leg-lock move the controller refuses is split: at the demo's motion limits the controller's planning
    refuses some moves between consecutive postures of the demo's plan (seed 0), as the
    loop could not keep the leg locked along their straight line; it accepts every piece
    of :func:`locked_path` between the same postures."""
    plans = plan_campaign(nominal, CampaignDesign(postures_per_leg=DEMO_POSTURES_PER_LEG,
                                                  envelope_fraction=DEMO_ENVELOPE_FRACTION, seed=0))
    postures = campaign_postures(plans, nominal.characteristic_length_mm)
    config, active = ControllerConfig(), ActiveGeometry.of(nominal, "nominal")
    budget = nominal.limits.leg_velocity_mm_s * (1.0 - config.calibration_ramp_fraction)  # as the controller plans

    def refusal(plan, start, goal) -> str | None:
        context = PlanningContext(active, DEMO_MOTION, config.loop.period_s, budget,
                                  LegLock(plan.leg, plan.locked_reading_mm), config.lock_max_correction_mm,
                                  config.path_step_mm, config.path_step_deg, config.lock_cycle_iterations)
        at_rest = KinematicState.at_rest(RelativeMmDeg._make(start).in_radians())
        planned = plan_path(context, at_rest, [Waypoint(goal)])
        return None if planned.ok else planned.refusal.code

    unsplit = []
    for plan in plans:
        poses = [np.zeros(6)] + [p.pose for p in postures if p.leg == plan.leg]
        for start, goal in zip(poses[:-1], poses[1:]):
            unsplit.append(refusal(plan, start, goal))
            path = locked_path(nominal, plan.leg, plan.locked_length_mm, start, goal)
            assert [refusal(plan, a, b) for a, b in zip([start] + path[:-1], path)] == [None] * len(path)
    assert set(unsplit) == {None, "lock_unreachable"}, "every unsplit move accepted: is the split still needed?"


def test_achieved_pose_inverts_the_measurement(nominal) -> None:
    relative = np.array([12.0, -30.0, 45.0, 1.5, -2.0, 7.0])
    absolute = absolute_from_relative(nominal.home, relative)
    model = np.array(nominal.measurement.feature_points)
    points = model @ rotation_matrix(*absolute[3:]).T + absolute[:3]
    assert achieved_pose(nominal, points) == pytest.approx(relative, abs=1e-9)


def test_improved_needs_both_largest_errors_down() -> None:
    before = ValidationSummary(20.0, 0.8, 10.0, 0.4)
    assert improved(before, ValidationSummary(0.2, 0.01, 0.1, 0.005))
    assert not improved(before, ValidationSummary(0.2, 0.9, 0.1, 0.005))
    assert not improved(before, ValidationSummary(25.0, 0.01, 0.1, 0.005))


def test_envelope_fraction_keeps_the_candidates_inside_the_scaled_envelope(nominal) -> None:
    free = plan_postures(nominal, PlanRequest(0, 5, candidates=200, envelope_fraction=0.4))
    assert free.ok
    assert np.all(np.abs(free.poses_relative) <= 0.4 * np.array(nominal.limits.pose_max))
    locked, wide = (plan_postures(nominal, PlanRequest(3, 5, candidates=200, envelope_fraction=f)) for f in (0.4, 1.0))
    assert np.max(np.abs(locked.poses_relative[:, :3])) < 0.6 * np.max(np.abs(wide.poses_relative[:, :3]))
    refused = plan_postures(nominal, PlanRequest(3, 5, envelope_fraction=0.0))
    assert refused.status is PlanStatus.INVALID_REQUEST and "envelope fraction" in refused.message


def test_largest_stroke_error_names_the_axis() -> None:
    achieved = np.array(X_SWEEP.waypoints, dtype=float)
    achieved[3, 0] += 6.0  # 1 % of X's 600 mm
    achieved[5, 3] += 0.46  # 2 % of roll's 23°
    fraction, axis = largest_stroke_error([MotionResult(X_SWEEP, achieved)], [600, 600, 250, 23, 23, 60])
    assert (fraction, axis) == (pytest.approx(0.02), 3)


def test_a_sentence_of_several_lines_is_forwarded_a_line_at_a_time() -> None:
    """The API takes one line of text for a display (``progress``'s ``said``): the demo's
    sentences of several lines were refused whole."""
    import io

    from hexactl.application.campaign.progress import Progress

    forwarded: list[dict] = []
    progress = Progress(io.StringIO(), io.StringIO())
    progress.forward_to(forwarded.append)
    progress.say("hexactl demo (seed 1): the experiment\n\n  measuring\n")
    assert [sent["said"] for sent in forwarded] == ["hexactl demo (seed 1): the experiment", "  measuring"]

