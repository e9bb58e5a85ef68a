"""How the campaign runner reaches a leg-lock posture (``runner._visit``): straight when
the controller takes the move; split along ``locked_path`` when it refuses the straight
line; by way of the zero posture when it refuses the pieces as out of limits; and a
refusal of any other kind ends the campaign with the controller's reason."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pytest

from hexactl.adapters.api.client import CommandError
from hexactl.application.campaign.driver import CampaignError
from hexactl.application.campaign.runner import ZERO_POSE, _visit
from hexactl.calibration.campaign import locked_path
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import leg_lengths
from hexactl.kinematics.pose import absolute_from_relative, pose_mm_deg_to_mm_rad

LEG = 2
START = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class ScriptedDriver:
    """A driver whose controller refuses the moves ``refuse`` names (a code, or None to
    take it) before they start; the moves it took and whether it settled after each."""

    def __init__(self, refuse: Callable[[int, Sequence[float]], str | None]) -> None:
        self.refuse = refuse
        self.here: Sequence[float] = START
        self.asked = 0
        self.taken: list[tuple[tuple[float, ...], bool]] = []

    def status(self) -> dict:
        return {"pose_command": list(self.here)}

    def move(self, pose: Sequence[float], settle: bool = True) -> dict:
        self.asked += 1
        if code := self.refuse(self.asked, pose):
            raise CommandError(code, f"scripted refusal of move {self.asked}")
        self.here = tuple(pose)
        self.taken.append((tuple(pose), settle))
        return {"pose_command": list(pose)}


def far_goal_on_the_constraint(nominal: Geometry, length_mm: float) -> tuple[float, ...]:
    """A posture with leg LEG at ``length_mm`` whose straight line from START strays far
    from that length (so ``locked_path`` splits it)."""
    for z in range(200, 0, -10):
        for x in (-150.0, 150.0):
            for roll in (-10.0, 10.0):
                goal = (x, 0.0, float(z), roll, 0.0, 0.0)
                path = locked_path(nominal, LEG, length_mm, START, goal)
                if len(path) >= 3:
                    return tuple(path[-1])
    raise AssertionError("no far posture found")


@pytest.fixture
def setting(nominal: Geometry) -> tuple[float, tuple[float, ...]]:
    length = float(leg_lengths(nominal.legs, absolute_from_relative(nominal.home, pose_mm_deg_to_mm_rad(list(START))))[LEG - 1])
    return length, far_goal_on_the_constraint(nominal, length)


def test_straight_when_the_controller_takes_it(nominal: Geometry, setting) -> None:
    length, goal = setting
    driver = ScriptedDriver(lambda n, pose: None)
    _visit(driver, nominal, LEG, length, goal)
    assert driver.taken == [(goal, True)]


def test_split_along_the_constraint_when_the_straight_move_is_refused(nominal: Geometry, setting) -> None:
    length, goal = setting
    driver = ScriptedDriver(lambda n, pose: "lock_unreachable" if n == 1 else None)
    _visit(driver, nominal, LEG, length, goal)
    pieces = locked_path(nominal, LEG, length, START, goal)
    assert len(pieces) >= 3
    assert driver.taken == [(tuple(p), False) for p in pieces[:-1]] + [(tuple(pieces[-1]), True)]


def test_by_the_zero_posture_when_the_pieces_are_out_of_limits(nominal: Geometry, setting) -> None:
    length, goal = setting
    driver = ScriptedDriver(lambda n, pose: {1: "lock_unreachable", 2: "path_violation"}.get(n))
    _visit(driver, nominal, LEG, length, goal)
    detour = locked_path(nominal, LEG, length, START, ZERO_POSE) + locked_path(nominal, LEG, length, ZERO_POSE, goal)
    assert [pose for pose, _ in driver.taken] == [tuple(p) for p in detour]
    assert driver.taken[-1] == (goal, True)


@pytest.mark.parametrize("refusals", [{1: "busy"}, {1: "lock_unreachable", 2: "leg_locked"},
                                      {1: "path_violation", 2: "path_violation", 3: "path_violation"}])
def test_any_other_refusal_ends_the_campaign_with_the_reason(nominal: Geometry, setting, refusals) -> None:
    length, goal = setting
    driver = ScriptedDriver(lambda n, pose: refusals.get(n))
    with pytest.raises(CampaignError, match=refusals[max(refusals)]):
        _visit(driver, nominal, LEG, length, goal)
