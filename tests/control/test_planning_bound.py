"""The bounds on planning's work (:data:`~hexactl.control.planning.MAX_WAYPOINTS`, counted
before any planning, and :data:`~hexactl.control.planning.PLANNING_BUDGET_S`, checked
inside planning): a request that would keep the API's worker for minutes is refused at
once with what to do, never planned. No wall-clock assertions: the budget's clock is
replaced where it is tested."""

from __future__ import annotations

import itertools

import pytest

from hexactl.adapters.files.sequence_file import sequence_from_plan, sequence_from_toml
from hexactl.control import planning
from hexactl.control.planning import MAX_WAYPOINTS, PLANNING_BUDGET_S, Waypoint, plan_path
from hexactl.control.sequences import MotionSequence, SequenceError, SequenceWaypoint
from hexactl.control.waves import WaveSpec


def tiny_toml(count: int) -> str:
    """The outside tester's file: ``count`` waypoints alternating z 0 and 0.001 mm."""
    return 'name="t"\n' + "".join("[[waypoint]]\npose=[0,0,%s,0,0,0]\n" % ("0.001" if i % 2 else "0")
                                  for i in range(count))


def tiny_waypoints(count: int) -> tuple[SequenceWaypoint, ...]:
    return tuple(SequenceWaypoint(pose=(0, 0, 0.001 if i % 2 else 0, 0, 0, 0)) for i in range(count))


@pytest.fixture
def no_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any planning beyond the count fails the test."""

    def planned(*args, **kwargs):
        raise AssertionError("planned a sequence beyond the bound")

    for name in ("_plan_segment", "_goal", "pose_allowed", "path_violations"):
        monkeypatch.setattr(planning, name, planned)


def limit_named(message: str, count: int) -> None:
    assert f"{count} waypoints" in message, message
    assert f"at most {MAX_WAYPOINTS}" in message, message
    assert f"split it into sequences of at most {MAX_WAYPOINTS} waypoints" in message, message


def test_the_testers_10000_waypoint_file_is_refused_when_read() -> None:
    with pytest.raises(SequenceError) as refused:
        sequence_from_toml(tiny_toml(10_000), "tiny10000.toml")
    limit_named(str(refused.value), 10_000)
    assert str(refused.value).startswith("tiny10000.toml: waypoint: ")


def test_a_plan_csv_beyond_the_bound_is_refused_when_read() -> None:
    poses = [(0.0, 0.0, 0.001 * (i % 2), 0.0, 0.0, 0.0) for i in range(MAX_WAYPOINTS + 1)]
    header = "leg,x,y,z,roll,pitch,yaw," + ",".join(f"l{i}_setpoint" for i in range(1, 7))
    rows = [",".join(["1", *map(str, pose), *["400"] * 6]) for pose in poses]
    with pytest.raises(SequenceError) as refused:
        sequence_from_plan("\n".join([header, *rows]), "big.csv")
    limit_named(str(refused.value), MAX_WAYPOINTS + 1)


def test_10000_waypoints_are_refused_before_any_planning_and_nothing_reaches_the_loop(rig, no_planning) -> None:
    """Past the model's check too (a sequence built without validation): the controller
    refuses before planning a single waypoint, and the loop never sees a Play."""
    rig.enabled()
    sequence = MotionSequence.model_construct(name="t", description="", frame="zero", waypoints=tiny_waypoints(10_000))
    for result in (rig.controller.play(sequence), rig.controller.validate_sequence(sequence)):
        assert not result.ok and result.error == "invalid_argument", result
        limit_named(result.message, 10_000)
        assert result.details["limit"] == MAX_WAYPOINTS and "pending" not in result.details, result
    rig.run(5)
    assert rig.controller.snapshot.sequence is None and rig.controller.snapshot.last_sequence is None
    assert rig.controller.snapshot.motion.value == "holding"


def test_one_waypoint_over_the_bound_is_refused_by_the_model() -> None:
    with pytest.raises(ValueError, match=f"split it into sequences of at most {MAX_WAYPOINTS} waypoints"):
        MotionSequence(name="t", waypoint=tiny_waypoints(MAX_WAYPOINTS + 1))


def test_a_sequence_at_the_bound_is_read_and_validated(rig) -> None:
    sequence = sequence_from_toml(tiny_toml(MAX_WAYPOINTS), "at_the_bound.toml")
    result = rig.controller.validate_sequence(sequence)
    assert result.ok and result.details["waypoints"] == MAX_WAYPOINTS, result


class SteppingClock:
    """A monotonic clock that moves ``step_s`` each time it is read."""

    def __init__(self, step_s: float) -> None:
        self._times = itertools.count(0.0, step_s)

    def __call__(self) -> float:
        return next(self._times)


def test_a_sequence_over_the_planning_budget_is_refused_naming_where(rig, monkeypatch: pytest.MonkeyPatch) -> None:
    """The clock read once at the start and once before each waypoint: 11 s a read spends
    the 60 s budget at the 6th look, waypoint 6."""
    monkeypatch.setattr(planning, "_clock", SteppingClock(PLANNING_BUDGET_S / 5.5))
    s = rig.controller.snapshot
    plan = plan_path(rig.controller._context(s), s.trajectory, [Waypoint(w.pose) for w in tiny_waypoints(20)])
    assert not plan.ok and plan.refusal.code == "planning_failed", plan.refusal
    assert plan.refusal.message.startswith(f"planning took longer than {PLANNING_BUDGET_S:g} s, at waypoint 6 of 20: "
                                           "split it into shorter sequences"), plan.refusal.message


def test_a_sequence_within_the_budget_is_planned(rig, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(planning, "_clock", SteppingClock(0.0))
    result = rig.controller.validate_sequence(MotionSequence(name="t", waypoint=tiny_waypoints(20)))
    assert result.ok and result.details["waypoints"] == 20, result


def test_a_wave_over_the_planning_budget_is_refused(rig, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 600 s wave (300,000 cycles at 500 Hz): the budget is looked at between batches of
    cycles, and a spent one refuses before the path is checked."""
    monkeypatch.setattr(planning, "_clock", SteppingClock(PLANNING_BUDGET_S * 2))
    spec = WaveSpec(frequency_hz=1.0, cycles=600, axes={"z": {"amplitude": 1.0}, "x": {"amplitude": 1.0}})
    result = rig.controller.validate_wave(spec)
    assert not result.ok and result.error == "planning_failed", result
    assert f"planning took longer than {PLANNING_BUDGET_S:g} s, at cycle" in result.message, result.message
