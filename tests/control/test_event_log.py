"""The loop's events numbered, and read on from a reader's last seen (the ``events``
request, ``hexactl events --follow``): each once, and what the loop no longer kept counted."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from hexactl.control.core import KEPT_EVENTS
from hexactl.control.snapshot import Event
from hexactl.control.telemetry import events_after


def _kept(first: int, count: int) -> tuple[Event, ...]:
    return tuple(Event(seq, 1_000 * seq, "stop", f"stop {seq}") for seq in range(first, first + count))


@given(first=st.integers(1, 500), count=st.integers(0, KEPT_EVENTS), after=st.integers(0, 700))
def test_a_reader_gets_each_kept_event_after_its_last_once_and_a_count_of_the_rest(first, count, after) -> None:
    kept = _kept(first, count)
    log = events_after(kept, 2_000_000_000, after)
    assert [event.seq for event in log.events] == [seq for seq in range(first, first + count) if seq > after]
    assert log.last == (first + count - 1 if count else 0) and log.t == 2.0
    missed = set(range(after + 1, log.last + 1)) - {event.seq for event in log.events}
    assert log.missed == len(missed)  # those after its last that the loop has dropped, none it keeps


def test_the_loop_numbers_its_events_one_after_another_past_what_it_keeps(rig) -> None:
    rig.enabled()
    for _ in range(KEPT_EVENTS + 5):
        rig.controller.stop()
        rig.run(2)
    log = rig.controller.events()
    assert len(log.events) == KEPT_EVENTS and log.missed == log.events[0].seq - 1 >= 5
    assert [event.seq for event in log.events] == list(range(log.last - KEPT_EVENTS + 1, log.last + 1))
    assert rig.controller.events(log.last).events == () and rig.controller.events(log.last - 2).missed == 0
