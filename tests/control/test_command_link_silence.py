"""The loop when its command link falls silent (control/motion_commands.py): a motion under
way brakes to rest and stays enabled, a paused sequence and a platform at rest are left as
they are, and each silence and its end are events."""

from __future__ import annotations

from hexactl.control import commands as cmd
from hexactl.control.sequences import MotionSequence, SequenceWaypoint

FAR = [300.0, 0, 0, 0, 0, 0]


def silent(rig, seconds: float = 1.2) -> None:
    rig.controller.thread.submit(cmd.CommandLinkSilent(0, silent_s=seconds))
    rig.run()


def events(rig, code: str) -> list[str]:
    return [event.message for event in rig.controller.events().events if event.code == code]


def test_a_move_under_way_brakes_to_rest_short_of_its_goal_and_stays_enabled(rig):
    rig.enabled()
    assert rig.controller.move(FAR, duration=10.0).ok
    rig.run(500)  # 1 s into 10
    silent(rig)
    assert rig.controller.snapshot.motion.value == "stopping"
    rig.settle()
    telemetry = rig.controller.telemetry()
    assert telemetry.state == "enabled" and 0 < telemetry.pose_command[0] < 100.0
    [message] = events(rig, "command_link_silent")
    assert "for 1.2 s" in message and "braked to rest" in message and "hardware E-stop" in message
    rig.assert_setpoints_safe()


def test_a_sequence_playing_is_ended_and_a_paused_one_left_to_resume(rig):
    rig.enabled()
    sequence = MotionSequence(name="out", waypoint=[SequenceWaypoint(pose=[0, 0, 10, 0, 0, 0], dwell=1.0),
                                                    SequenceWaypoint(pose=[0, 0, 0, 0, 0, 0])])
    assert rig.controller.play(sequence).ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")  # at rest, yet under way
    silent(rig)
    assert rig.controller.telemetry().sequence is None
    assert "braked to rest" in events(rig, "command_link_silent")[-1]

    assert rig.controller.play(sequence).ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "dwelling")
    assert rig.controller.pause().ok
    rig.run_until(lambda: rig.controller.telemetry().sequence.phase == "paused")
    silent(rig)
    assert rig.controller.telemetry().sequence.phase == "paused"
    assert "nothing was moving" in events(rig, "command_link_silent")[-1]
    assert rig.controller.resume().ok


def test_at_rest_and_disabled_nothing_changes_but_the_events_say_so(rig):
    silent(rig, 3.4)
    assert rig.controller.snapshot.state.value == "disabled"
    rig.enabled()
    silent(rig)
    rig.controller.thread.submit(cmd.CommandLinkHeard(0, silent_s=2.5))
    rig.run()
    assert rig.controller.snapshot.state.value == "enabled" and rig.controller.snapshot.motion.value == "holding"
    at_rest, enabled = events(rig, "command_link_silent")
    assert "for 3.4 s" in at_rest and "for 1.2 s" in enabled
    assert "nothing was moving" in at_rest and "nothing was moving" in enabled
    assert events(rig, "command_link_heard") == ["the API is heard again after 2.5 s of silence"]
    assert rig.controller.move(FAR).ok  # the next command is taken as ever
