"""Sequences: the file format, the built-ins, playback and the dwell records."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexactl.adapters.files.sequence_file import dwell_header, dwell_rows, sequence_from_toml
from hexactl.control.sequences import BUILTIN_SEQUENCES, SequenceError, builtin_sequence, sequence_from_mapping

TEXT = """
name = "two_steps"
description = "a test"

[[waypoint]]
pose = [50.0, 0.0, 0.0, 0.0, 0.0, 0.0]
duration = 2.0
dwell = 0.5

[[waypoint]]
pose = [0.0, 0.0, 20.0, 0.0, 2.0, 0.0]
speed = 0.5
"""


def test_the_file_format_round_trips_into_waypoints():
    sequence = sequence_from_toml(TEXT, "two_steps.toml")
    assert sequence.name == "two_steps" and len(sequence.waypoints) == 2
    first, second = sequence.planning_waypoints()
    assert (first.pose, first.duration_s, first.speed, first.dwell_s) == ((50.0, 0, 0, 0, 0, 0), 2.0, None, 0.5)
    assert (second.speed, second.dwell_s) == (0.5, 0.0)


@pytest.mark.parametrize(("text", "problem"), [
    ("name = 'x'", "waypoint"),
    ("name = 'x'\n[[waypoint]]\npose = [1, 2, 3]", "pose"),
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, nan]", "finite"),
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\nduration = 1\nspeed = 0.5", "not both"),
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\nspeed = 2", "speed"),
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\ndwell = -1", "dwell"),
    # an unknown key is answered with the keys taken there, and the nearest
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\nwait = 1",
     r"^bad.toml: waypoint\[0\].wait: not a key here; the keys here are duration, speed, pose, dwell$"),
    ("name = 'x'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\ndwel = 1", r"waypoint\[0\].dwel: not a key here; did you mean dwell\?"),
    ("name = 'x'\nframes = 'work'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]",
     r"frames: not a key here; did you mean frame\? the keys here are name, description, frame, waypoint$"),
    ("name = ", "TOML"),
    ("name = 'x'\n[waypoint]\npose = [0, 0, 0, 0, 0, 0]", r"write each waypoint as \[\[waypoint\]\]"),
    (f"name = '{'x' * 201}'\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]", "name: String should have at most 200"),
    # the log writes the name: a line end would forge the lines after it, an escape recolour a terminal
    ('name = "a\\nsequence_finished"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]',
     r"name: 'a\\nsequence_finished': a sequence's name is one line of printable text"),
    ('name = "a\\u001b[31m"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]', "one line of printable text"),
    ('name = "a\\u2028b"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]', "one line of printable text"),  # a line end too
])
def test_bad_files_name_the_problem(text, problem):
    with pytest.raises(SequenceError, match=problem):
        sequence_from_toml(text, "bad.toml")


def test_a_name_is_any_one_line_of_text_as_the_apis_sources_are():
    """One rule for every name the log writes (hexactl/kinematics/one_line.py)."""
    assert sequence_from_toml('name = "Prüfung 2 – ε"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]', "f.toml").name == \
        "Prüfung 2 – ε"


def test_builtins_are_the_paper_test_motions():
    assert set(BUILTIN_SEQUENCES) == {"x_sweep", "y_rotation", "compound"}
    x_sweep = builtin_sequence("x_sweep")
    assert [w.pose[0] for w in x_sweep.waypoints] == [600, 450, 300, 150, 0, -150, -300, -450, -600]
    assert [w.pose[4] for w in builtin_sequence("y_rotation").waypoints] == [20, 15, 10, 5, 0, -5, -10, -15, -20]
    assert [w.pose for w in builtin_sequence("compound").waypoints] == [(0,) * 6, (100, 100, 100, 5, 5, 5)]


@pytest.mark.parametrize("name", BUILTIN_SEQUENCES)
def test_every_builtin_validates_on_the_nominal_platform(rig, name):
    result = rig.controller.validate_sequence(name)
    assert result.ok, result.message
    assert result.details["waypoints"] == len(builtin_sequence(name).waypoints)


def test_a_sequence_is_validated_from_where_the_motion_under_way_ends_and_while_disabled(rig):
    """play waits for rest, so its validation plans from the move's goal at rest, as a wave's
    does: from the moving state, its first waypoint was planned as a move that replaces
    the running one, which play never runs. Disabled, it validates all the same."""
    steps = sequence_from_mapping({"name": "steps", "waypoint": [{"pose": [0, 0, 20, 0, 0, 0]}]})
    disabled = rig.controller.validate_sequence(steps)
    assert disabled.ok, disabled.message
    rig.enabled()
    assert rig.controller.move([60, 0, 0, 0, 0, 0], duration=2.0).ok
    rig.run(100)  # under way
    while_moving = rig.controller.validate_sequence(steps)
    rig.settle()
    at_goal = rig.controller.validate_sequence(steps)
    assert while_moving.ok and at_goal.ok
    assert while_moving.details["duration_s"] == pytest.approx(at_goal.details["duration_s"], rel=1e-9)
    assert at_goal.details["duration_s"] > disabled.details["duration_s"]  # from x 60, not from zero


def test_a_validation_while_disabled_plans_from_where_the_platform_is(make_rig):
    """Found from outside: disabled, the validations planned from where the generator was
    left (zero at start-up; the last move's goal after a disable), not from where the
    platform is, which is where enabling starts it: a path error did not show before
    enabling, or one showed that was not there."""
    from hexactl.control.waves import WaveSpec

    rig = make_rig(start_pose=(60, 0, 0, 0, 0, 0))  # started away from zero, never enabled
    rig.run(3)
    steps = sequence_from_mapping({"name": "steps", "waypoint": [{"pose": [0, 0, 20, 0, 0, 0]}]})
    wave = WaveSpec(frequency_hz=0.5, cycles=2, axes={"x": {"amplitude": 20.0}})
    controller = rig.controller
    disabled = (controller.validate_sequence(steps), controller.validate_wave(wave),
                controller.validate_pose([5, 0, 0, 0, 0, 0], relative=True))
    rig.enabled()
    enabled = (controller.validate_sequence(steps), controller.validate_wave(wave),
               controller.validate_pose([5, 0, 0, 0, 0, 0], relative=True))
    for before, after in zip(disabled, enabled):
        assert before.ok and after.ok, (before.message, after.message)
        assert before.details.keys() == after.details.keys()
        for key, value in before.details.items():  # one key at a time: pytest ≥ 9.2's approx takes no nesting
            expected = after.details[key]
            assert value == (pytest.approx(expected) if isinstance(expected, (float, list)) else expected), key
    assert disabled[2].details["goal"] == pytest.approx([65, 0, 0, 0, 0, 0], abs=1e-6)  # by 5 from where it is


def test_play_records_commanded_and_measured_pose_at_each_dwell(rig):
    rig.enabled()
    sequence = sequence_from_toml(TEXT)
    result = rig.controller.play(sequence)
    assert result.ok and result.details["waypoints"] == 2
    rig.run(5)
    assert rig.controller.telemetry().sequence.name == "two_steps"
    rig.settle()
    report = rig.controller.sequence_records()
    assert report.status == "finished" and [r.waypoint for r in report.records] == [1, 2]
    first, second = report.records
    assert first.pose_command == pytest.approx((50, 0, 0, 0, 0, 0), abs=1e-9)
    assert first.pose_measured == pytest.approx((50, 0, 0, 0, 0, 0), abs=1e-3)
    assert second.pose_command == pytest.approx((0, 0, 20, 0, 2, 0), abs=1e-9)
    assert second.t_s - first.t_s >= 0.5  # the dwell was kept
    rows = dwell_rows(report.records)
    assert len(rows) == 2 and all(len(row) == len(dwell_header()) for row in rows)
    assert rows[0][:3] == ["two_steps", 1, first.t_s]
    rig.assert_setpoints_safe()


def test_a_sequence_with_one_bad_waypoint_is_refused_before_anything_moves(rig):
    rig.enabled()
    text = TEXT + "\n[[waypoint]]\npose = [0.0, 0.0, 0.0, 0.0, 0.0, 70.0]\n"
    sent = len(rig.sent)
    result = rig.controller.play(sequence_from_toml(text))
    assert not result.ok and result.error == "path_violation"
    assert result.details["violations"][0]["waypoint"] == 3
    rig.run(100)
    assert (rig.sent[sent:] == rig.sent[sent - 1]).all()
    assert rig.controller.telemetry().sequence is None


def test_pause_mid_move_resume_and_finish_on_the_path(rig):
    rig.enabled()
    assert rig.controller.play("compound").ok
    rig.run(5)  # waypoint 1 is the zero posture: already there, dwelling
    rig.run_until(lambda: rig.controller.telemetry().sequence.index == 2)
    rig.run(300)
    refused = rig.controller.resume()
    assert refused.error == "not_paused" and refused.message.endswith("pause it first"), refused
    assert rig.controller.pause().ok
    rig.run(2)
    # Found from outside: resumed while still braking, the refusal said only "pausing, not paused".
    refused = rig.controller.resume()
    assert refused.error == "not_paused" and "resume once it is paused" in refused.message, refused
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "paused")
    paused = rig.controller.telemetry().pose_command
    rig.run(200)
    assert rig.controller.telemetry().pose_command == paused  # stays paused
    assert 0 < paused[0] < 100
    # Paused on the straight line towards (100, 100, 100, 5, 5, 5): all axes in proportion.
    assert paused == pytest.approx([paused[0] * v / 100 for v in (100, 100, 100, 5, 5, 5)], rel=1e-6)
    assert rig.controller.pause().error == "already_paused"
    resumed_to_the_end(rig)
    assert rig.controller.telemetry().loop.guard_clamps == 0


def resumed_to_the_end(rig) -> None:
    """Resume the paused ``compound``: it finishes on its last waypoint, every set-point safe."""
    assert rig.controller.resume().ok
    rig.settle()
    report = rig.controller.sequence_records()
    assert report.status == "finished" and len(report.records) == 2
    assert report.records[1].pose_command == pytest.approx((100, 100, 100, 5, 5, 5), abs=1e-9)
    rig.assert_setpoints_safe()


def test_pause_during_a_dwell_freezes_its_clock(rig):
    rig.enabled()
    sequence = sequence_from_toml(TEXT)
    assert rig.controller.play(sequence).ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")
    assert rig.controller.pause().ok
    rig.run(1000)  # far longer than the 0.5 s dwell
    assert rig.controller.telemetry().sequence.phase == "paused"
    assert rig.controller.sequence_records().records == ()
    assert rig.controller.resume().ok
    rig.settle()
    assert len(rig.controller.sequence_records().records) == 2


def test_abort_brakes_and_keeps_the_records(rig):
    rig.enabled()
    assert rig.controller.play("x_sweep").ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.index == 2)
    rig.run(200)
    assert rig.controller.abort().ok
    rig.settle()
    assert ("abort", "the sequence ends, braking to rest") in [(e.code, e.message) for e in rig.controller.snapshot.events]
    report = rig.controller.sequence_records()
    assert report.status == "aborted" and len(report.records) == 1
    assert report.records[0].pose_command == pytest.approx((600, 0, 0, 0, 0, 0), abs=1e-9)
    assert 450 < rig.controller.telemetry().pose_command[0] < 600  # braked on the way
    assert rig.controller.abort().error == "no_sequence"
    assert rig.controller.resume().error == "no_sequence"
    rig.assert_setpoints_safe()


def test_sequence_blocks_other_motion_commands(rig):
    rig.enabled()
    assert rig.controller.play("compound").ok
    rig.run(2)
    assert rig.controller.move([10, 0, 0, 0, 0, 0]).error == "busy"
    assert rig.controller.play("compound").error == "busy"
    assert rig.controller.disable().error == "busy"
    assert rig.controller.resume().error == "not_paused"
    unknown = rig.controller.play("nonsense")
    assert unknown.error == "unknown_sequence" and unknown.details["built_in"] == list(BUILTIN_SEQUENCES), unknown
    assert rig.controller.play(42).error == "invalid_argument"


@pytest.mark.parametrize("poses", [
    # Roll 2.2° → 4.6°: the loop started it from where ruckig ended the first move, 1e-13 off
    # the goal the planner started from, and ruckig refused it there: planner_error.
    [(207.3, -94.6, -62.3, 2.2, -1.3, -19.5), (207.3, -94.6, -62.3, 4.6, -1.3, 3.2)],
    # Steps of 2.4° in pitch: refused as planning_failed (ruckig 0.19.4 fails at that distance).
    [(0, 0, 0, 0, 1.2, 0), (0, 0, 0, 0, 3.6, 0), (0, 0, 0, 0, 6.0, 0)],
])
def test_sequences_ruckig_used_to_refuse_are_accepted_and_played_to_the_end(rig, poses):
    rig.enabled()
    result = rig.controller.play(sequence_from_mapping({"name": "steps", "waypoint": [{"pose": p} for p in poses]}))
    assert result.ok, result.message
    rig.settle()
    _assert_finished_on(rig, poses)


# Poses as typed (tenths of mm and deg) within 30 % of the envelope, where every pose is valid.
typed_poses = st.tuples(*[st.integers(-3 * limit, 3 * limit).map(lambda tenths: tenths / 10)
                          for limit in (600, 600, 250, 23, 23, 60)])


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=typed_poses, axis=st.integers(0, 5), sign=st.sampled_from([-1, 1]), last=typed_poses)
def test_rest_to_rest_sequences_are_accepted_and_played_to_the_end(make_rig, first, axis, sign, last):
    """Three waypoints, the second one step of 2·a³/j² from the first on one axis (40 mm,
    24 mm, 2.4°, 3.6°: where ruckig 0.19.4 fails): planned, and played without a fault."""
    second = list(first)
    second[axis] = round(second[axis] + sign * (40, 40, 24, 2.4, 2.4, 3.6)[axis], 1)
    poses = [first, tuple(second), last]
    rig = make_rig().enabled()
    result = rig.controller.play(sequence_from_mapping({"name": "typed", "waypoint": [{"pose": p} for p in poses]}))
    assert result.ok, result.message
    rig.settle()
    _assert_finished_on(rig, poses)


def _assert_finished_on(rig, poses):
    snapshot = rig.controller.snapshot
    assert snapshot.state.value == "enabled" and snapshot.faults == (), snapshot.faults
    report = rig.controller.sequence_records()
    assert report.status == "finished"
    assert np.array([record.pose_command for record in report.records]) == pytest.approx(np.array(poses), abs=1e-9)
    rig.assert_setpoints_safe()


@pytest.mark.parametrize("cycles_before_the_end", [1, 2, 3, 5, 8, 13, 21, 34, 55, 89])
def test_a_pause_in_a_moves_deceleration_resumes_and_finishes_on_the_path(make_rig, cycles_before_the_end):
    """A pause is a halt: in a segment's deceleration it may run on to the segment's goal
    (a halt never ends beyond the goal of the move under way), and resume then has nothing
    left of that move: the sequence goes on and finishes as planned."""
    rig = make_rig()
    rig.enabled()
    assert rig.controller.play("compound").ok
    rig.run_until(lambda: (t := rig.controller.telemetry()).sequence.index == 2 and t.remaining_s is not None)
    rig.run_until(lambda: rig.controller.telemetry().remaining_s <= cycles_before_the_end * rig.period_ns / 1e9)
    assert rig.controller.pause().ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "paused")
    paused = rig.controller.telemetry().pose_command
    assert paused == pytest.approx([paused[0] * v / 100 for v in (100, 100, 100, 5, 5, 5)], rel=1e-6)  # on the line
    assert all(p <= g + 1e-9 for p, g in zip(paused, (100, 100, 100, 5, 5, 5)))  # never past the goal
    resumed_to_the_end(rig)
