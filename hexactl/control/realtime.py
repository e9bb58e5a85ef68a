"""Real-time set-up of the loop's thread: scheduling, CPU affinity, memory locking and
the garbage collector. Every step is optional, none is required to run: without the
privilege a step is skipped and :class:`RealtimeReport` says what was obtained.

The GIL. Every thread of the process that runs Python competes with the loop for the
GIL; the service keeps the API, its parsing and planning in another process
(:mod:`hexactl.application.loop_link`, whose loop side runs in the loop thread itself), so
what remains beside the loop are short bursts that end by blocking: with the simulator,
the simulated firmwares answering each cycle's frames. Once a thread asks for the GIL, the
holder gives it up after at most ``switch_interval_s`` (plus its longest C call). The
interval is set longer than a cycle with its spin and exchange (1 ms): a cycle is then
never forced off the GIL halfway for such a burst (at 0.1 ms the simulator, woken by the
cycle's first frames, could take it before the cycle ends), while a thread that would not
let go still delays the loop by at most 1 ms (BENCHMARKS.md compares 0.1, 1 and 5 ms).
A thread that the kernel preempts *while holding the GIL* stalls the loop for as long as
it is preempted — a priority inversion SCHED_FIFO on the loop alone cannot prevent: run
the process's other threads at a SCHED_FIFO priority just below the loop's
(``hexactl serve`` does, unless ``--no-realtime``).

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
import resource
import sys
import threading
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field
from hexactl.kinematics.numbers import Flag, Number, WholeNumber

_MCL_CURRENT = 1
_MCL_FUTURE = 2
_CAP_IPC_LOCK = 14
_CAP_SYS_NICE = 23

DEFAULT_FIFO_PRIORITY = 80
"""The loop's SCHED_FIFO priority when the service runs real-time (its default): above
the kernel's threaded interrupt handlers (50) and most real-time services, below the
kernel's own watchdog and migration threads (99)."""


class RealtimeConfig(BaseModel):
    """What to ask the operating system for. The defaults need no privilege."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fifo_priority: WholeNumber | None = Field(
        default=None, ge=1, le=99, description="SCHED_FIFO priority of the loop thread; None: normal scheduling"
    )
    cpus: tuple[WholeNumber, ...] | None = Field(default=None, description="CPUs the loop thread may run on; None: any")
    lock_memory: Flag = Field(default=False, description="mlockall(MCL_CURRENT | MCL_FUTURE): no page faults")
    switch_interval_s: Number | None = Field(
        default=0.001,
        gt=0,
        description="sys.setswitchinterval while running: how long another thread may keep the GIL once the "
        "loop asks for it, and how long the loop may keep it once another asks (longer than a cycle, so no "
        "cycle is cut in two; CPython's default, 5 ms, is 2.5 periods at 500 Hz); None: leave it",
    )
    manage_gc: Flag = Field(default=True, description="apply the garbage collection policy of this module")
    gc_interval_s: Number = Field(default=1.0, gt=0, description="period of the loop's young-generation collection")


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


@dataclass(frozen=True, slots=True)
class Privileges:
    """What this process may ask for: ``sys_nice`` (CAP_SYS_NICE: any SCHED_FIFO
    priority), ``rtprio_limit`` (RLIMIT_RTPRIO: the highest SCHED_FIFO priority without
    it), ``ipc_lock`` (CAP_IPC_LOCK: lock any amount of memory), ``memlock_limit_bytes``
    (RLIMIT_MEMLOCK without it; None: unlimited)."""

    sys_nice: bool
    rtprio_limit: int
    ipc_lock: bool
    memlock_limit_bytes: int | None


def probe_privileges() -> Privileges:
    """This process's :class:`Privileges`, from its effective capabilities
    (``/proc/self/status``; none if unreadable) and resource limits. Root normally has
    both capabilities; root in a container may have neither."""
    try:
        status = Path("/proc/self/status").read_text(encoding="ascii")
        capabilities = int(next(line.split()[1] for line in status.splitlines() if line.startswith("CapEff:")), 16)
    except (OSError, StopIteration, ValueError, IndexError):
        capabilities = 0
    memlock = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    return Privileges(sys_nice=bool(capabilities >> _CAP_SYS_NICE & 1),
                      rtprio_limit=resource.getrlimit(resource.RLIMIT_RTPRIO)[0],
                      ipc_lock=bool(capabilities >> _CAP_IPC_LOCK & 1),
                      memlock_limit_bytes=None if memlock == resource.RLIM_INFINITY else memlock)


def allowed(config: RealtimeConfig, privileges: Privileges) -> tuple[int | None, bool, tuple[str, ...]]:
    """What of ``config``'s scheduling and memory locking ``privileges`` allow: (the
    SCHED_FIFO priority to set, None for normal scheduling; whether to lock memory; a
    note per request left out or lowered, saying why and how to get it).

    Without CAP_SYS_NICE the priority is capped at RLIMIT_RTPRIO. Without CAP_IPC_LOCK
    memory is locked only under an unlimited RLIMIT_MEMLOCK: ``MCL_FUTURE`` under a finite
    one would make every allocation past it fail, which is worse than a page fault."""
    notes: list[str] = []
    priority = config.fifo_priority
    if priority is not None and not privileges.sys_nice and privileges.rtprio_limit < priority:
        limit = privileges.rtprio_limit
        if limit <= 0:
            notes.append(f"SCHED_FIFO {priority} not set: needs root, CAP_SYS_NICE or RLIMIT_RTPRIO > 0 "
                         "(ulimit -r, limits.conf rtprio); normal scheduling")
            priority = None
        else:
            notes.append(f"SCHED_FIFO {limit}, not {priority}: RLIMIT_RTPRIO is {limit} and there is no CAP_SYS_NICE")
            priority = limit
    lock = config.lock_memory
    if lock and not privileges.ipc_lock and privileges.memlock_limit_bytes is not None:
        notes.append(f"memory not locked: RLIMIT_MEMLOCK is {privileges.memlock_limit_bytes} bytes and there is no "
                     "CAP_IPC_LOCK (ulimit -l unlimited, limits.conf memlock)")
        lock = False
    return priority, lock, tuple(notes)


def describe(report: RealtimeReport) -> str:
    """``report`` in one line for a log: what was obtained, then the notes."""
    scheduling = f"SCHED_FIFO {report.fifo_priority}" if report.fifo_priority is not None else "normal scheduling"
    memory = "memory locked" if report.memory_locked else "memory not locked"
    return "; ".join((f"{scheduling}, {memory}", *report.notes))


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
    A process such a thread starts begins with normal scheduling (SCHED_RESET_ON_FORK).
    """
    try:
        os.sched_setscheduler(native_id, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except (OSError, AttributeError) as error:
        return f"SCHED_FIFO {priority} not set: {error}"
    return None


def fifo_for_threads(priority: int, names: Collection[str]) -> dict[str, str | None]:
    """SCHED_FIFO at ``priority`` for each of this process's running threads called one of
    ``names``: thread name to None when done, else :func:`set_fifo`'s note why not."""
    return {thread.name: set_fifo(priority, thread.native_id) for thread in threading.enumerate()
            if thread.name in names and thread.native_id is not None}


def apply_realtime(config: RealtimeConfig, privileges: Privileges | None = None) -> tuple[RealtimeReport, _Previous]:
    """Apply ``config`` to the calling thread (scheduling, affinity) and the process
    (memory, GIL switch interval, gc), as far as ``privileges`` (None: probed) allow
    (:func:`allowed`). Never raises for a missing privilege."""
    wanted_priority, wanted_lock, skipped = allowed(config, privileges or probe_privileges())
    notes = list(skipped)
    previous = _Previous(gc.isenabled(), sys.getswitchinterval(), False)

    priority = None
    if wanted_priority is not None:
        # Thread 0 is the calling thread on Linux: only the loop thread becomes real-time.
        if (refused := set_fifo(wanted_priority)) is None:
            priority = wanted_priority
        else:  # the probe said yes, the kernel no: e.g. a cgroup without real-time runtime
            notes.append(refused)

    cpus = None
    if config.cpus is not None:
        try:
            os.sched_setaffinity(0, set(config.cpus))
            cpus = tuple(sorted(os.sched_getaffinity(0)))
        except (OSError, ValueError, AttributeError) as error:
            notes.append(f"CPU affinity {list(config.cpus)} not set: {error}")

    locked = False
    if wanted_lock:
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
