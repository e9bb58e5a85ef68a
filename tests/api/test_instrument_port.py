"""The simulated instrument's own port between the service's two processes: the API's
process asks, the loop's process answers with the drives' true positions."""

from __future__ import annotations

import multiprocessing
import threading

import pytest

from hexactl.adapters.api.commands import MeasurementError
from hexactl.application.simulator import InstrumentLine, InstrumentPort

POSITIONS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


def _ask_from_another_process(line_end, answers) -> None:
    line = InstrumentLine(line_end)
    answers.put([line() for _ in range(3)])


def test_each_request_is_answered_with_the_positions_now() -> None:
    now = list(POSITIONS)
    port = InstrumentPort(lambda: now).start()
    line = InstrumentLine(port.line_end)
    try:
        assert line() == POSITIONS
        now[0] = 10.0
        assert line() == (10.0, *POSITIONS[1:])
    finally:
        port.close()


def test_the_line_works_from_a_spawned_process_as_the_api_uses_it() -> None:
    context = multiprocessing.get_context("spawn")
    port = InstrumentPort(lambda: POSITIONS).start()
    answers = context.Queue()
    child = context.Process(target=_ask_from_another_process, args=(port.line_end, answers))
    child.start()
    try:
        assert answers.get(timeout=60) == [POSITIONS] * 3
    finally:
        child.join(60)
        port.close()
    assert child.exitcode == 0


def test_a_late_answer_to_a_timed_out_request_is_not_taken_for_the_next_one() -> None:
    release = threading.Event()
    values = iter([(0.0,) * 6, POSITIONS])

    def slow_first() -> tuple[float, ...]:
        value = next(values)
        if value == (0.0,) * 6:
            release.wait(10)
        return value

    port = InstrumentPort(slow_first).start()
    line = InstrumentLine(port.line_end)
    try:
        with pytest.raises(MeasurementError, match="did not answer within 0.2 s"):
            line(timeout_s=0.2)
        release.set()  # the first answer now arrives, after its request timed out
        assert line() == POSITIONS  # only the matching answer ends the wait
    finally:
        release.set()
        port.close()


def test_a_closed_port_is_a_measurement_error_not_a_hang() -> None:
    port = InstrumentPort(lambda: POSITIONS).start()
    line = InstrumentLine(port.line_end, timeout_s=10.0)
    port.close()
    with pytest.raises(MeasurementError, match="closed"):
        line()
