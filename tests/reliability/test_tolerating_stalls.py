"""The test suite's own tolerance of a loaded host (:func:`tests.reliability.support.tolerating_stalls`):
a scenario whose move the service braked because its API process fell silent (the
process held up, as a starved host does, here by SIGSTOP) runs again, and passes, as does
one a command of which was answered ``loop_timeout``; a scenario that fails without any
stall fails at once.

A real ``hexactl serve`` in a process of its own, as tests/api/test_frozen_api.py runs it.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.can.bus_monitor import MONITOR_THREAD_NAME
from tests.api.test_service import at_rest, status
from tests.reliability.support import braked_since, hold_up_api, last_event, recover, tolerating_stalls
from tools.serving import HANG_S, serve, wait_until

GOAL = [0.0, 0.0, 20.0, 0.0, 0.0, 0.0]


def resting(client: HexactlClient) -> dict:
    return wait_until(lambda: at_rest(client), "the platform at rest", HANG_S, seen=lambda: status(client))


def test_a_move_braked_on_the_api_silence_is_tried_again_and_a_plain_failure_is_not(tmp_path: Path) -> None:
    with serve(tmp_path) as served, HexactlClient(served.api, timeout_s=10) as client:
        recover(client)
        attempts = []

        def braked_then_moves() -> None:
            attempts.append(last_event(status(client)))
            client.call("move", pose=GOAL, duration=30.0 if len(attempts) == 1 else 1.0)
            if len(attempts) == 1:
                wait_until(lambda: status(client)["motion"] == "moving", "the move under way", HANG_S)
                hold_up_api(served)
            assert resting(client)["pose_command"] == pytest.approx(GOAL, abs=1e-6)

        tolerating_stalls(client, braked_then_moves)
        assert len(attempts) == 2 and braked_since(client, attempts[0]) and not braked_since(client, attempts[1])

        failures = []

        def fails() -> None:
            failures.append(1)
            raise AssertionError("a scenario's own failure")

        with pytest.raises(AssertionError, match="own failure"):
            tolerating_stalls(client, fails)
        assert failures == [1]

        # A command the loop gave no verdict on in time (a host holding the loop up past the
        # API's limit, seen beside three dashboard suites at load 40) is a stall; another
        # refusal is the scenario's own failure.
        replies = []

        def refused(code: str) -> Callable[[], None]:
            def scenario() -> None:
                replies.append(code)
                if len(replies) == 1:
                    raise CommandError(code, "as the service says it")
            return scenario

        tolerating_stalls(client, refused("loop_timeout"))
        assert replies == ["loop_timeout"] * 2
        replies.clear()
        with pytest.raises(CommandError, match="not_enabled"):
            tolerating_stalls(client, refused("not_enabled"))
        assert replies == ["not_enabled"]


def test_the_threads_sharing_an_in_process_loop_run_just_below_it(service, monitor) -> None:
    """pytest's thread and the bus monitor's share the GIL of the service's loop in this
    process: at normal priority they held it up past the watchdog on a loaded host
    (``service_here``), so they run just below it, as ``hexactl serve``'s own threads do."""
    priority = service.controller.thread.loop.realtime.fifo_priority
    expected = (os.SCHED_OTHER, 0) if priority is None else (os.SCHED_FIFO, priority - 1)
    [monitor_thread] = [thread for thread in threading.enumerate() if thread.name == MONITOR_THREAD_NAME]
    for thread in (threading.current_thread(), monitor_thread):
        policy = os.sched_getscheduler(thread.native_id) & ~os.SCHED_RESET_ON_FORK
        assert (policy, os.sched_getparam(thread.native_id).sched_priority) == expected, thread.name
