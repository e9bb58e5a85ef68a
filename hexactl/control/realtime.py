"""Real-time set-up of the loop's thread: scheduling, CPU affinity, memory locking and
the garbage collector. Every step is optional, none is required to run: without the
privilege a step is skipped and :class:`RealtimeReport` says what was obtained.

The GIL. Every thread of the process that runs Python competes with the loop for the
GIL; the service keeps the API, its parsing and planning in another process
(:mod:`hexactl.adapters.loop_link`, whose loop side runs in the loop thread itself), so
what remains beside the loop are short bursts that end by blocking: with the simulator,
the simulated firmwares answering each cycle's frames. Once a thread asks for the GIL, the
holder gives it up after at most ``switch_interval_s`` (plus its longest C call). The
interval is set longer than a cycle with its spin and exchange (1 ms against about
0.6 ms): a cycle is then never forced off the GIL halfway for such a burst (at 0.1 ms the
simulator, woken by the cycle's first frames, could take it before the cycle ends), while
a thread that would not let go still delays the loop by at most 1 ms. Measured
(BENCHMARKS.md), 0.1, 1 and 5 ms differ by less than the run-to-run noise. A thread that the
kernel preempts *while holding the GIL* stalls the loop for as long as it is preempted —
a priority inversion SCHED_FIFO on the loop alone cannot prevent: run the process's
other threads at a SCHED_FIFO priority just below the loop's (``hexactl serve --fifo``
does).

Garbage collection policy (why: a cyclic collection of the whole heap can stop every
thread for milliseconds at a moment the collector picks):

- at start: ``gc.collect()`` then ``gc.freeze()`` (everything alive moves to the
  permanent generation, never scanned again) then ``gc.disable()`` — process-wide, so
  the caller threads' allocations no longer trigger collections either;
- while running, the loop itself runs ``gc.collect(1)`` (generations 0 and 1: only
  objects created since the previous run) every ``gc_interval_s``, in a cycle's slack
  (after its work, when at least half a period is left); :class:`~hexactl.control.stats.LoopStats`
  reports how many ran and the longest;
- generation 2 is not collected while the loop runs: cyclic garbage that lived through
  two young collections (> ``gc_interval_s``) stays until shutdown
  (:func:`restore_process`). The loop's own cycle creates no reference cycles.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import sys
from dataclasses import dataclass, field

from pydantic import BaseModel, ConfigDict, Field

_MCL_CURRENT = 1
_MCL_FUTURE = 2


class RealtimeConfig(BaseModel):
    """What to ask the operating system for. The defaults need no privilege."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fifo_priority: int | None = Field(
        default=None, ge=1, le=99, description="SCHED_FIFO priority of the loop thread; None: normal scheduling"
    )
    cpus: tuple[int, ...] | None = Field(default=None, description="CPUs the loop thread may run on; None: any")
    lock_memory: bool = Field(default=False, description="mlockall(MCL_CURRENT | MCL_FUTURE): no page faults")
    switch_interval_s: float | None = Field(
        default=0.001,
        gt=0,
        description="sys.setswitchinterval while running: how long another thread may keep the GIL once the "
        "loop asks for it, and how long the loop may keep it once another asks (longer than a cycle, so no "
        "cycle is cut in two; CPython's default, 5 ms, is 2.5 periods at 500 Hz); None: leave it",
    )
    manage_gc: bool = Field(default=True, description="apply the garbage collection policy of this module")
    gc_interval_s: float = Field(default=1.0, gt=0, description="period of the loop's young-generation collection")


@dataclass(frozen=True, slots=True)
class RealtimeReport:
    """What the loop thread obtained. ``notes``: one line per step that was skipped or
    failed, with the reason."""

    fifo_priority: int | None = None
    cpus: tuple[int, ...] | None = None
    memory_locked: bool = False
    switch_interval_s: float | None = None
    gc_managed: bool = False
    notes: tuple[str, ...] = field(default=())


@dataclass(slots=True)
class _Previous:
    """What :func:`apply_realtime` changed process-wide, to put back at shutdown."""

    gc_enabled: bool
    switch_interval_s: float
    memory_locked: bool


def set_fifo(priority: int, native_id: int = 0) -> str | None:
    """Put thread ``native_id`` (``threading.Thread.native_id``; 0: the calling thread)
    under SCHED_FIFO at ``priority``. None when done, else a note saying why not (no
    privilege, no such thread); never raises.

    Threads that share the GIL with the loop need it too: one preempted by another
    process while it holds the GIL stalls the loop however high the loop's priority.
    """
    try:
        os.sched_setscheduler(native_id, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as error:
        return f"SCHED_FIFO {priority} not set: {error}"
    return None


def apply_realtime(config: RealtimeConfig) -> tuple[RealtimeReport, _Previous]:
    """Apply ``config`` to the calling thread (scheduling, affinity) and the process
    (memory, GIL switch interval, gc). Never raises for a missing privilege."""
    notes: list[str] = []
    previous = _Previous(gc.isenabled(), sys.getswitchinterval(), False)

    priority = None
    if config.fifo_priority is not None:
        # Thread 0 is the calling thread on Linux: only the loop thread becomes real-time.
        if (refused := set_fifo(config.fifo_priority)) is None:
            priority = config.fifo_priority
        else:
            notes.append(refused)

    cpus = None
    if config.cpus is not None:
        try:
            os.sched_setaffinity(0, set(config.cpus))
            cpus = tuple(sorted(os.sched_getaffinity(0)))
        except (OSError, ValueError, AttributeError) as error:
            notes.append(f"CPU affinity {list(config.cpus)} not set: {error}")

    locked = False
    if config.lock_memory:
        error_text = _mlockall()
        if error_text is None:
            locked = previous.memory_locked = True
        else:
            notes.append(f"mlockall failed: {error_text}")

    switch = None
    if config.switch_interval_s is not None:
        sys.setswitchinterval(config.switch_interval_s)
        switch = sys.getswitchinterval()

    if config.manage_gc:
        gc.collect()
        gc.freeze()
        gc.disable()

    report = RealtimeReport(priority, cpus, locked, switch, config.manage_gc, tuple(notes))
    return report, previous


def restore_process(config: RealtimeConfig, previous: _Previous) -> None:
    """Undo the process-wide parts of :func:`apply_realtime` (thread settings end with
    the thread)."""
    if config.manage_gc:
        gc.unfreeze()
        if previous.gc_enabled:
            gc.enable()
    if config.switch_interval_s is not None:
        sys.setswitchinterval(previous.switch_interval_s)
    if previous.memory_locked:
        _libc().munlockall()


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)


def _mlockall() -> str | None:
    """None on success, else the reason."""
    try:
        libc = _libc()
    except OSError as error:
        return f"no libc: {error}"
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
        return os.strerror(ctypes.get_errno())
    return None
