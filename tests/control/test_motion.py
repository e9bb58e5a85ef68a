"""The motion part alone (trajectory → set-point path → playback, the leg lock, the plan
epoch), on the nominal geometry without a core or hardware."""

from __future__ import annotations

import pytest

from hexactl.control.config import ControllerConfig
from hexactl.control.motion import Motion
from hexactl.control.planning import ActiveGeometry, Segment
from hexactl.control.results import ErrorCode
from hexactl.control.snapshot import MotionState
from hexactl.kinematics.inverse import sensor_setpoints

CONFIG = ControllerConfig()
PERIOD_NS = CONFIG.loop.period_ns
ZERO = (0.0,) * 6
GOAL = (5.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class Rig:
    def __init__(self, geometry) -> None:
        self.active = ActiveGeometry.of(geometry, "nominal")
        self.log: list[str] = []
        self.motion = Motion(CONFIG, self.active, CONFIG.loop.period_s, lambda name, waypoint: (name, waypoint),
                             lambda code, message: self.log.append(code))
        self.now_ns = 0
        self.motion.start(ZERO, self.ik(ZERO))

    def ik(self, pose) -> list[float]:
        return sensor_setpoints(self.active.geometry.legs, self.active.absolute_from_relative_mm_rad(pose))

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.now_ns += PERIOD_NS
            assert self.motion.update(self.active, self.now_ns) is None

    def settle(self, limit: int = 5000) -> None:
        for _ in range(limit):
            if not self.motion.trajectory.moving and not self.motion.player.playing:
                return
            self.run(1)
        raise AssertionError("still moving")


@pytest.fixture
def rig(geometry) -> Rig:
    return Rig(geometry)


def segment(goal=GOAL, dwell_s=0.0) -> Segment:
    return Segment(goal, 1.0, 1.0, dwell_s, 1.0)


def test_a_move_runs_to_its_goal_and_the_setpoints_follow(rig):
    assert rig.motion.epoch == 1  # start advanced it
    assert rig.motion.move(segment()) is None
    assert rig.motion.state(enabled=True) is MotionState.MOVING
    assert rig.motion.state(enabled=False) is MotionState.HOLDING
    rig.settle()
    assert rig.motion.path.pose_command == pytest.approx(GOAL, abs=1e-9)
    assert rig.motion.path.setpoints == pytest.approx(rig.ik(GOAL), abs=1e-9)


def test_a_plan_from_another_epoch_is_stale(rig):
    assert rig.motion.stale(rig.motion.epoch) is None
    refusal = rig.motion.stale(rig.motion.epoch - 1)
    assert refusal is not None and refusal[0] is ErrorCode.STALE_PLAN


def test_stop_brakes_ends_the_sequence_and_advances_the_epoch(rig):
    rig.motion.player.play("tour", (segment(), segment(ZERO)))
    rig.run(20)
    epoch = rig.motion.epoch
    rig.motion.stop()
    assert rig.motion.epoch == epoch + 1 and rig.motion.state(enabled=True) is MotionState.STOPPING
    assert rig.motion.player.report.status == "aborted"
    rig.settle()
    assert rig.motion.state(enabled=True) is MotionState.HOLDING


def test_freeze_keeps_the_commanded_pose_and_forgets_the_rest(rig):
    rig.motion.player.play("tour", (segment(),))
    rig.motion.path.hold(rig.motion.path.pose_command, [s + 0.5 for s in rig.motion.path.setpoints])
    rig.motion.swap(rig.active, enabled=True)  # a ramp under way
    rig.run(20)
    pose, setpoints, epoch = rig.motion.path.pose_command, rig.motion.path.setpoints, rig.motion.epoch
    rig.motion.freeze("fault", "a fault latched: following_error")
    assert not rig.motion.trajectory.moving and rig.motion.trajectory.position == pytest.approx(pose)
    assert not rig.motion.path.ramp.active and rig.motion.player.report.status == "fault"
    assert (rig.motion.path.pose_command, rig.motion.path.setpoints) == (pose, setpoints)
    assert rig.motion.epoch == epoch + 1


def test_lock_holds_the_sent_setpoint_and_unlock_is_bumpless(rig):
    rig.motion.lock_leg(3)
    assert rig.motion.lock.leg == 3 and rig.motion.lock.sensor_mm == rig.motion.path.setpoints[2]
    assert rig.motion.move(segment((1.0, 0.0, 0.0, 0.0, 0.0, 0.0))) is None
    rig.settle()
    assert rig.motion.path.setpoints[2] == rig.motion.lock.sensor_mm
    projected = list(rig.motion.path.pose_command)
    epoch = rig.motion.epoch
    rig.motion.unlock_leg()
    assert rig.motion.lock is None and rig.motion.epoch == epoch + 1
    assert list(rig.motion.trajectory.position) == projected  # the generator starts where the platform was held


def test_a_refused_resume_leaves_the_epoch(rig):
    rig.motion.player.play("tour", (segment(),))
    rig.motion.pause(rig.now_ns)
    while rig.motion.trajectory.moving:  # braking
        rig.run(1)
    epoch = rig.motion.epoch
    assert rig.motion.resume(None, rig.now_ns) is not None and rig.motion.epoch == epoch
    assert rig.motion.resume(segment(), rig.now_ns) is None and rig.motion.epoch == epoch + 1
