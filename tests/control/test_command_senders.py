"""Who sent what (control/submitter.py ``commands_from``, control/command_inbox.py): every
command carries its sender to the loop, and every event the loop records while carrying
it out names that sender; what the loop does of its own accord names none."""

from __future__ import annotations

from hexactl.control.sequences import MotionSequence, SequenceWaypoint
from hexactl.control.submitter import commands_from

ALICE = "hexactl alice@bench-2 (pid 4242, uid 1000)"
BOB = "dashboard, browser 10.0.0.7 (127.0.0.1)"


def recorded(rig, since: int = 0) -> list[tuple[str, str | None]]:
    """The loop's events after the first ``since``: (code, sender)."""
    return [(event.code, event.sender) for event in rig.controller.events().events[since:]]


def test_each_command_names_its_sender_in_the_event_it_leaves(rig):
    with commands_from(ALICE):
        assert rig.controller.enable().ok
    rig.run(2)
    with commands_from(BOB):
        assert rig.controller.move([0, 0, 20, 0, 0, 0], duration=2.0).ok
    rig.run(50)
    with commands_from(ALICE):
        assert rig.controller.stop().ok
    rig.settle()
    with commands_from(ALICE):
        assert rig.controller.disable().ok
    rig.run()
    assert recorded(rig) == [("enabled", ALICE), ("move", BOB), ("stop", ALICE), ("disabled", ALICE)]
    move = next(event for event in rig.controller.events().events if event.code == "move")
    assert move.message == ("2 s as planned, to 0.000 0.000 20.000 0.000 0.000 0.000 (mm, deg; relative to the zero "
                            "posture)")  # where it went, for who reads the log after an incident


def test_an_estop_names_who_pressed_it_in_its_fault_and_a_refusal_names_who_was_refused(rig):
    rig.enabled()
    before = len(rig.controller.events().events)
    with commands_from(ALICE):
        assert rig.controller.move([0, 0, 5, 0, 0, 0], deadline_ns=rig.clock()).ok  # handed over; the loop finds it expired
    rig.run()
    with commands_from(BOB):
        assert rig.controller.estop().ok
    rig.run()
    [fault] = rig.controller.snapshot.faults
    assert fault.message == f"estop command from {BOB}"
    with commands_from(ALICE):
        assert rig.controller.reset().ok
    rig.run()
    assert recorded(rig, before) == [("command_refused", ALICE), ("estop", BOB), ("reset", ALICE)]


def test_what_the_loop_does_of_its_own_accord_names_no_sender(rig):
    rig.enabled()
    before = len(rig.controller.events().events)
    sequence = MotionSequence(name="up", waypoint=[SequenceWaypoint(pose=[0, 0, 5, 0, 0, 0])])
    with commands_from(ALICE):
        assert rig.controller.play(sequence).ok
    rig.run_until(lambda: rig.controller.snapshot.sequence is None)
    # The sequence's start is Alice's doing, recorded by the sequence player itself; its
    # end came cycles later, from the plan.
    assert recorded(rig, before) == [("sequence_started", ALICE), ("sequence_finished", None)]


def test_a_caller_in_the_loops_own_process_is_no_one_in_particular(rig):
    rig.enabled()
    assert {sender for _, sender in recorded(rig)} == {None}


def test_a_stream_closed_by_another_client_names_who_closed_it(rig):
    """Found from outside: a stream_close left only the stream's end, named by no one (the
    loop ends it once braked), so "who closed my stream?" had no answer."""
    rig.enabled()
    with commands_from(ALICE):
        assert rig.controller.stream_open("sim", timeout_s=1.0).ok
    rig.run(2)
    before = len(rig.controller.events().events)
    with commands_from(BOB):
        assert rig.controller.stream_close().ok
    rig.settle()
    assert recorded(rig, before) == [("stream_closed", BOB), ("stream_ended", None)]
