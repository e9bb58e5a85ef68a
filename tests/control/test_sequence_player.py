"""The sequence player alone, on a stand-in trajectory generator: waypoint by waypoint,
dwells and their records, pause and resume mid-move and mid-dwell, abort."""

from __future__ import annotations

from math import isnan, radians

import pytest

from hexactl.control.hardware import ActuatorFeedback, ActuatorState, FeedbackSnapshot
from hexactl.control.planning import Segment
from hexactl.control.results import ErrorCode
from hexactl.control.sequence_player import SequencePhase, SequencePlayer, dwell_record
from hexactl.control.trajectory import StepResult
from hexactl.kinematics.axes import RelativeMmRad

S = 1_000_000_000


class Trajectory:
    """What the player uses of PoseTrajectory: it records the calls."""

    def __init__(self) -> None:
        self.goals: list[tuple] = []
        self.halts = 0
        self.moving = False
        self.frames = None  # relative coordinates, as every segment here

    def move_to(self, goal, time_scale=1.0, velocity_scale=1.0) -> bool:
        self.goals.append((tuple(goal), time_scale, velocity_scale))
        self.moving = True
        return True

    def halt(self) -> None:
        self.halts += 1


def segment(x: float, dwell_s: float = 1.0) -> Segment:
    return Segment((x, 0.0, 0.0, 0.0, 0.0, 0.0), 1.5, 0.5, dwell_s, 2.0)


SEGMENTS = (segment(10.0), segment(20.0, dwell_s=0.0), segment(30.0))


class Rig:
    def __init__(self) -> None:
        self.trajectory = Trajectory()
        self.records: list[tuple[str, int]] = []
        self.log: list[tuple[str, str]] = []
        self.player = SequencePlayer(self.trajectory, self._record, lambda code, message: self.log.append((code, message)))

    def _record(self, name: str, waypoint: int):
        self.records.append((name, waypoint))
        return f"record {waypoint}"  # the player keeps whatever the core makes

    def arrive(self, now_ns: int) -> None:
        self.trajectory.moving = False
        self.player.update(StepResult.FINISHED, now_ns)


@pytest.fixture
def rig() -> Rig:
    rig = Rig()
    rig.player.play("tour", SEGMENTS)
    return rig


def test_play_heads_for_the_first_waypoint(rig):
    assert rig.trajectory.goals == [((10.0, 0, 0, 0, 0, 0), 1.5, 0.5)]
    progress = rig.player.progress
    assert (progress.name, progress.waypoint, progress.phase, progress.total) == ("tour", 1, SequencePhase.MOVING, 3)
    assert rig.player.report.status == "playing" and rig.player.report.records == ()
    assert rig.log == [("sequence_started", "sequence 'tour': 3 waypoints")]


def test_each_waypoint_dwells_then_records_then_the_next_starts(rig):
    rig.player.update(StepResult.WORKING, 1 * S)
    assert rig.player.progress.phase is SequencePhase.MOVING
    rig.arrive(2 * S)
    assert rig.player.progress.phase is SequencePhase.DWELLING
    rig.player.update(StepResult.IDLE, 3 * S - 1)
    assert rig.records == [] and len(rig.trajectory.goals) == 1
    rig.player.update(StepResult.IDLE, 3 * S)  # the dwell of 1 s is over
    assert rig.records == [("tour", 1)]
    assert rig.trajectory.goals[-1][0][0] == 20.0
    assert (rig.player.progress.waypoint, rig.player.progress.phase) == (2, SequencePhase.MOVING)
    rig.arrive(4 * S)  # no dwell: recorded and on in the cycle of arrival
    assert rig.records == [("tour", 1), ("tour", 2)] and rig.player.progress.waypoint == 3


def test_the_last_dwell_finishes_the_sequence_with_every_record(rig):
    for t in (1, 2, 3):
        rig.arrive(10 * t * S)
        rig.player.update(StepResult.IDLE, (10 * t + 1) * S)
    assert rig.player.progress is None and not rig.player.playing
    assert rig.player.report.status == "finished"
    assert rig.player.report.records == ("record 1", "record 2", "record 3")
    assert rig.log[-1] == ("sequence_finished", "sequence 'tour' finished after 3 of 3 waypoints")


def test_pause_mid_move_brakes_and_resume_needs_the_rest_of_the_move(rig):
    rig.player.pause(1 * S)
    assert rig.trajectory.halts == 1 and rig.player.progress.phase is SequencePhase.PAUSING
    rig.player.update(StepResult.WORKING, 2 * S)  # still braking
    assert rig.player.progress.phase is SequencePhase.PAUSING
    rig.trajectory.moving = False
    rig.player.update(StepResult.FINISHED, 3 * S)  # at rest: paused, not arrived
    assert rig.player.progress.phase is SequencePhase.PAUSED and rig.player.progress.paused_in_move
    refusal = rig.player.resume(None, 4 * S)
    assert refusal is not None and refusal[0] is ErrorCode.INVALID_ARGUMENT
    assert rig.player.progress.phase is SequencePhase.PAUSED
    rest = segment(10.0)
    assert rig.player.resume(rest, 4 * S) is None
    assert rig.trajectory.goals[-1][0] == rest.goal and rig.player.progress.phase is SequencePhase.MOVING
    assert rig.player.progress.waypoint == 1


def test_pause_mid_dwell_keeps_what_is_left_of_it(rig):
    rig.arrive(10 * S)  # dwells until 11 s
    rig.player.pause(10 * S + 400_000_000)
    assert rig.trajectory.halts == 0 and rig.player.progress.phase is SequencePhase.PAUSED
    rig.player.update(StepResult.IDLE, 50 * S)
    assert rig.records == []  # paused: the dwell does not end
    assert rig.player.resume(None, 100 * S) is None
    rig.player.update(StepResult.IDLE, 100 * S + 599_999_999)
    assert rig.records == []
    rig.player.update(StepResult.IDLE, 100 * S + 600_000_000)
    assert rig.records == [("tour", 1)]


def test_ending_keeps_the_records_and_a_second_end_does_nothing(rig):
    rig.arrive(1 * S)
    rig.player.update(StepResult.IDLE, 2 * S)
    rig.player.end("aborted")
    assert rig.player.report.status == "aborted" and rig.player.report.records == ("record 1",)
    assert rig.log[-1] == ("sequence_aborted", "sequence 'tour' aborted after 1 of 3 waypoints")
    rig.player.end("fault")
    assert rig.player.report.status == "aborted" and len(rig.log) == 2
    rig.player.update(StepResult.FINISHED, 3 * S)  # nothing playing: nothing happens
    assert rig.records == [("tour", 1)]


def test_a_new_sequence_starts_with_no_records(rig):
    rig.arrive(1 * S)
    rig.player.update(StepResult.IDLE, 2 * S)
    rig.player.end("aborted")
    rig.player.play("again", (segment(5.0),))
    assert rig.player.report.name == "again" and rig.player.report.records == ()


def test_a_dwell_record_is_in_mm_and_degrees_and_nan_without_feedback():
    pose = RelativeMmRad(1.0, 2.0, 3.0, radians(10), radians(-20), radians(30))
    legs = FeedbackSnapshot(tuple(ActuatorFeedback(float(i), 0.0, ActuatorState.ENABLED, 0, (), 0.0, 0) for i in range(6)), 0)
    record = dwell_record("tour", 2, 3 * S, pose, None, [5.0] * 6, legs)
    assert (record.sequence, record.waypoint, record.t_s) == ("tour", 2, 3.0)
    assert record.pose_command == pytest.approx((1.0, 2.0, 3.0, 10.0, -20.0, 30.0))
    assert record.pose_measured is None
    assert record.leg_setpoints == (5.0,) * 6 and record.leg_feedback == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
    blind = dwell_record("tour", 2, 3 * S, pose, pose, [5.0] * 6, None)
    assert blind.pose_measured == pytest.approx(record.pose_command) and all(isnan(v) for v in blind.leg_feedback)
