"""The real-time default falls back cleanly without the privilege: what is asked for is
decided from the process's capabilities and limits (injected here: the tests run as
root), each step left out is noted with why, and ``hexactl serve --no-realtime`` asks for
nothing."""

from __future__ import annotations

import os
from dataclasses import replace

import pytest

import hexactl.application.service as service_module
from hexactl.adapters.cli.main import main
from hexactl.control import realtime
from hexactl.control.realtime import (
    DEFAULT_FIFO_PRIORITY,
    Privileges,
    RealtimeConfig,
    RealtimeReport,
    allowed,
    apply_realtime,
    describe,
    probe_privileges,
    restore_process,
)

DEFAULT = RealtimeConfig(fifo_priority=DEFAULT_FIFO_PRIORITY, lock_memory=True)
ROOT = Privileges(sys_nice=True, rtprio_limit=0, ipc_lock=True, memlock_limit_bytes=8 << 20)
USER = Privileges(sys_nice=False, rtprio_limit=0, ipc_lock=False, memlock_limit_bytes=8 << 20)


def test_with_the_capabilities_everything_asked_for_is_allowed() -> None:
    assert allowed(DEFAULT, ROOT) == (DEFAULT_FIFO_PRIORITY, True, ())


def test_without_any_privilege_normal_scheduling_and_unlocked_memory_with_the_reasons() -> None:
    priority, lock, notes = allowed(DEFAULT, USER)
    assert (priority, lock) == (None, False)
    assert len(notes) == 2
    assert "CAP_SYS_NICE or RLIMIT_RTPRIO > 0" in notes[0] and "normal scheduling" in notes[0]
    assert "RLIMIT_MEMLOCK is 8388608 bytes" in notes[1] and "CAP_IPC_LOCK" in notes[1]


def test_rlimit_rtprio_caps_the_priority_and_an_unlimited_memlock_allows_locking() -> None:
    limited = replace(USER, rtprio_limit=40, memlock_limit_bytes=None)
    priority, lock, notes = allowed(DEFAULT, limited)
    assert (priority, lock) == (40, True)
    assert notes == (f"SCHED_FIFO 40, not {DEFAULT_FIFO_PRIORITY}: RLIMIT_RTPRIO is 40 and there is no CAP_SYS_NICE",)
    assert allowed(RealtimeConfig(fifo_priority=30), limited)[:2] == (30, False)  # within the limit; no lock asked


def test_nothing_asked_for_nothing_noted() -> None:
    assert allowed(RealtimeConfig(), USER) == (None, False, ())


def test_apply_realtime_falls_back_without_trying_and_says_why(monkeypatch) -> None:
    def refuse(*arguments: object) -> None:
        raise AssertionError("tried without the privilege")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(realtime, "_mlockall", refuse)
    report, previous = apply_realtime(replace_config(DEFAULT), USER)
    restore_process(replace_config(DEFAULT), previous)
    assert report.fifo_priority is None and not report.memory_locked and len(report.notes) == 2
    assert describe(report).startswith("normal scheduling, memory not locked; SCHED_FIFO 80 not set: needs root")


def replace_config(config: RealtimeConfig) -> RealtimeConfig:
    """``config`` without the process-wide parts (GIL interval, gc) a test should not touch."""
    return config.model_copy(update={"manage_gc": False, "switch_interval_s": None})


def test_describe_says_what_was_obtained() -> None:
    assert describe(RealtimeReport(fifo_priority=80, memory_locked=True)) == "SCHED_FIFO 80, memory locked"


def test_the_probe_reads_this_process() -> None:
    privileges = probe_privileges()
    assert privileges.rtprio_limit >= 0
    if os.geteuid() == 0:  # the tests run as root, normally with the full capability set
        assert privileges.sys_nice and privileges.ipc_lock


@pytest.mark.parametrize(("options", "expected"), [
    ((), (DEFAULT_FIFO_PRIORITY, True)),
    (("--fifo", "60"), (60, True)),
    (("--no-realtime",), (None, False)),
    (("--no-realtime", "--mlock"), (None, False)),  # --mlock is accepted and changes nothing
])
def test_serve_asks_for_real_time_unless_told_not_to(options, expected, monkeypatch) -> None:
    asked = []
    monkeypatch.setattr(service_module, "run_service", lambda config: asked.append(config) or 0)
    assert main(["serve", *options]) == 0
    assert (asked[0].fifo_priority, asked[0].lock_memory) == expected


def test_fifo_and_no_realtime_together_are_refused(capsys) -> None:
    with pytest.raises(SystemExit) as refused:
        main(["serve", "--no-realtime", "--fifo", "60"])
    assert refused.value.code == 2 and "not allowed with argument" in capsys.readouterr().err
