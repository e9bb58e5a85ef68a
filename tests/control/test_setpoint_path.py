"""The set-point path alone: target pose → (leg-lock projection) → IK → calibration
ramp → locked leg held → guard, and what it keeps (commanded pose, set-points, clamps)."""

from __future__ import annotations

import pytest

from hexactl.control.config import ControllerConfig
from hexactl.control.planning import ActiveGeometry, LegLock
from hexactl.control.setpoint_path import SetpointPath
from hexactl.kinematics.inverse import leg_lengths, sensor_setpoints

PERIOD_S = 0.002
ZERO = (0.0,) * 6


class Rig:
    def __init__(self, geometry, config: ControllerConfig = ControllerConfig()) -> None:
        self.active = ActiveGeometry.of(geometry, "nominal")
        self.log: list[str] = []
        self.path = SetpointPath(config, self.active, PERIOD_S, lambda code, message: self.log.append(code))
        self.path.hold(ZERO, self.ik(ZERO))

    def ik(self, pose) -> list[float]:
        return sensor_setpoints(self.active.geometry.legs, self.active.absolute_from_relative_mm_rad(pose))


@pytest.fixture
def rig(geometry) -> Rig:
    return Rig(geometry)


def test_a_reachable_target_becomes_its_ik_setpoints(rig):
    target = (0.1, -0.06, 0.04, 0.0001, 0.0, -0.00008)
    assert rig.path.follow(rig.active, None, target, None) is None
    assert rig.path.setpoints == pytest.approx(rig.ik(target), abs=1e-12)
    assert rig.path.pose_command == target
    assert rig.path.clamped_cycles == 0 and rig.log == []


def test_the_guard_limits_a_jump_and_the_first_clamp_is_logged_once(rig):
    start = list(rig.path.setpoints)
    step_mm = rig.active.geometry.limits.leg_velocity_mm_s * PERIOD_S
    for _ in range(2):
        rig.path.follow(rig.active, None, (50.0, 0, 0, 0, 0, 0), None)
    assert all(abs(s - b) <= 2 * step_mm + 1e-9 for s, b in zip(rig.path.setpoints, start))
    assert rig.path.clamped_cycles == 2 and rig.path.clamped_legs
    assert rig.log == ["guard_clamped"]


def test_the_clamped_legs_are_those_of_every_clamp_so_far(rig):
    for leg in (0, 1):  # one leg held 5 mm off, then another: each is clamped in its cycle
        held = rig.ik(ZERO)
        held[leg] += 5.0
        rig.path.hold(ZERO, held)
        rig.path.follow(rig.active, None, ZERO, None)
    assert (rig.path.clamped_cycles, rig.path.clamped_legs) == (2, 0b11)


def test_a_locked_leg_stays_at_its_reading_and_the_pose_moves_on_the_constraint(rig):
    lock = LegLock(2, rig.path.setpoints[1])
    previous = ZERO
    for x in (0.2, 0.4, 0.6):
        target = (x, 0.0, 0.0, 0.0, 0.0, 0.0)
        assert rig.path.follow(rig.active, lock, target, previous) is None
        previous = target
        assert rig.path.setpoints[1] == lock.sensor_mm  # exactly, not IK's rounding
        pose = rig.path.pose_command
        length = leg_lengths(rig.active.geometry.legs, rig.active.absolute_from_relative_mm_rad(pose))[1]
        assert length == pytest.approx(lock.length_mm(rig.active.geometry), abs=1e-6)
        assert pose != list(target)  # projected


def test_a_failed_projection_is_a_fault_and_changes_nothing(geometry):
    rig = Rig(geometry, ControllerConfig(lock_cycle_iterations=1))
    before = (rig.path.pose_command, rig.path.setpoints)
    fault = rig.path.follow(rig.active, LegLock(1, rig.path.setpoints[0]), (10.0, 0, 0, 0, 0, 0), ZERO)
    assert fault is not None and (fault.code, fault.leg) == ("leg_lock_projection", 1)
    assert (rig.path.pose_command, rig.path.setpoints) == before


def test_a_swap_ramps_only_when_enabled(rig):
    rig.path.swap(rig.active, enabled=False)
    assert not rig.path.ramp.active
    rig.path.hold(ZERO, [s + 1.0 for s in rig.ik(ZERO)])  # being sent: 1 mm off the new geometry's
    rig.path.swap(rig.active, enabled=True)
    assert rig.path.ramp.active
    rig.path.follow(rig.active, None, ZERO, None)
    assert rig.path.setpoints == pytest.approx([s + 1.0 for s in rig.ik(ZERO)], abs=1e-9)  # the ramp's first cycle
