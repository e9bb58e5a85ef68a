"""A pose stream in the loop: follow the newest target, brake when the stream goes quiet.

A client opens a stream (:mod:`hexactl.control.stream_commands`) and sends target poses
many times a second; the API's process checks each one against the workspace (a target
out of reach is replaced by the reachable pose nearest to it along the way) and hands
the loop the newest, at most one a cycle. :class:`StreamFollower` is the loop's part:
each target becomes the trajectory generator's new goal (ruckig, online: jerk-limited,
replanned from the current state, arriving at rest on the target if no newer one
comes), so the platform follows the stream with a lag set by the stream's limits and
never faster than they allow (its velocity box shaped per target so that no leg exceeds
its speed: :func:`~hexactl.control.stream_commands.stream_velocity_limits`). Nothing is refused mid-stream: a stream cannot be refused
sample by sample.

Its timeout is the stream's deadman: once a cycle finds no target for longer than the
stream's timeout (the client stopped, lost its network or stalled; for the first target,
:data:`FIRST_TARGET_WAIT_NS` at least), the trajectory
brakes to rest along its path (under the stream's acceleration and jerk, as its
receiver's reachability check assumed) and the stream ends with that reason. ``stop`` ends it the
same way; a fault, an E-stop or ``disable`` end it at once.

Times monotonic ns. Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import StrEnum

from hexactl.control.trajectory import MotionLimits, PoseTrajectory
from hexactl.kinematics.axes import PerAxis, RelativeMmRad, ToolInWorkMmRad


HORIZON_S = 0.05
"""How far ahead of a moving stream's newest target the loop aims, at least: the target
extrapolated along the stream's velocity by this, to be reached at that velocity in no
less than this (ruckig's minimum duration; longer when targets come less often:
:mod:`hexactl.control.stream_commands`). A tracker that aims at the target itself, to pass it at its
velocity, has no distance to reach that velocity in and backs up first; one that aims at
rest on it lags by its braking distance (v²/2a + v·a/2j). Shorter follows closer and
reacts harder to a noisy stream."""


FIRST_TARGET_WAIT_NS = 1_000_000_000
"""How long a stream waits for its first target at least, whatever its timeout: until it
comes the platform holds at rest, so waiting costs nothing in safety, and a sender often
connects its socket (a CURVE handshake, on a loaded host) only once ``stream_open`` has
answered, which took longer than a 100 ms timeout and ended streams before they began."""


class StreamPhase(StrEnum):
    FOLLOWING = "following"  # following the newest target (at rest on it when none newer came)
    BRAKING = "braking"  # timed out, stopped or closed: braking to rest, then the stream ends


@dataclass(frozen=True, slots=True)
class StreamProgress:
    """The stream under way as published: ``stream`` its number (the ticket that opened
    it), ``source`` as the client named it, ``frame`` its poses' frame (a
    :class:`~hexactl.control.frames.Frame` value), ``timeout_ns`` its deadman,
    ``targets`` taken by the loop, ``last_sequence`` the sender's number of the newest,
    ``last_target_ns`` when the loop took it (monotonic) and ``latency_ns`` from its
    arrival in the API's process to that cycle, whose set-points carry it."""

    stream: int
    source: str
    frame: str
    phase: StreamPhase
    timeout_ns: int
    targets: int = 0
    last_sequence: int | None = None
    last_target_ns: int = 0
    latency_ns: int | None = None


@dataclass(frozen=True, slots=True)
class StreamReport:
    """How the last stream ended: ``reason`` for people, ``targets`` the loop took."""

    stream: int
    reason: str
    targets: int


class StreamFollower:
    """The deadman and the targets of the stream running on ``trajectory`` under the
    stream's ``limits`` (``ControllerConfig.stream``); ``log(code, message)`` notes
    opening and ending."""

    def __init__(self, trajectory: PoseTrajectory, limits: MotionLimits, log: Callable[[str, str], None]) -> None:
        self._trajectory = trajectory
        self._limits = limits
        self._log = log
        self._reason = ""
        self.progress: StreamProgress | None = None
        """The stream under way as published; made anew when a target arrives, not every cycle."""
        self.report: StreamReport | None = None

    @property
    def open(self) -> bool:
        """A stream is following (not braking to its end)."""
        return self.progress is not None and self.progress.phase is StreamPhase.FOLLOWING

    @property
    def braking_limits(self) -> MotionLimits | None:
        """The limits to brake a stream under (its own, which its receiver's reachability
        check assumed); None when no stream is under way."""
        return self._limits if self.progress is not None else None

    def start(self, stream: int, source: str, frame: str, timeout_ns: int, now_ns: int) -> None:
        """Stream ``stream`` starts (the trajectory at rest where it begins)."""
        self.progress = StreamProgress(stream, source, frame, StreamPhase.FOLLOWING, timeout_ns, last_target_ns=now_ns)
        self._log("stream_opened", f"stream {stream} from {source!r} in the {frame} frame, timeout "
                  f"{timeout_ns / 1e6:g} ms")

    def target(self, stream: int, goal: RelativeMmRad | ToolInWorkMmRad, velocity: PerAxis, max_velocity: PerAxis,
               horizon_s: float, sequence: int, received_ns: int, now_ns: int,
               min_velocity: PerAxis | None = None) -> None:
        """Head for ``goal`` (in the trajectory's coordinates), passing it at ``velocity``
        (mm/s, rad/s) in no less than ``horizon_s``, each axis within ``min_velocity``
        (None: ``-max_velocity``) and ``max_velocity``.
        A target for a stream that is not following (it ended or is braking) is ignored:
        it was on its way when the stream ended."""
        progress = self.progress
        if progress is None or progress.stream != stream or progress.phase is not StreamPhase.FOLLOWING:
            return
        self._trajectory.follow(goal, velocity, self._limits, max_velocity, horizon_s, min_velocity)
        self.progress = replace(progress, targets=progress.targets + 1, last_sequence=sequence,
                                last_target_ns=now_ns, latency_ns=now_ns - received_ns)

    def brake(self, reason: str) -> None:
        """End the stream: brake to rest (the caller halts the trajectory), then it ends as ``reason``."""
        if self.progress is not None and self.progress.phase is StreamPhase.FOLLOWING:
            self.progress = replace(self.progress, phase=StreamPhase.BRAKING)
            self._reason = reason

    def end(self, reason: str) -> None:
        """End the stream at once (the motion was frozen)."""
        if self.progress is not None:
            self.report = StreamReport(self.progress.stream, reason, self.progress.targets)
            self._log("stream_ended", f"stream {self.progress.stream}: {reason}")
            self.progress = None

    def before_step(self, now_ns: int) -> None:
        """Brake if no target came within the timeout by ``now_ns`` (the first target:
        within :data:`FIRST_TARGET_WAIT_NS`, if longer)."""
        progress = self.progress
        if progress is None or progress.phase is not StreamPhase.FOLLOWING:
            return
        quiet_ns = now_ns - progress.last_target_ns
        if progress.targets:
            if quiet_ns > progress.timeout_ns:
                self._trajectory.halt(self._limits)
                self.brake(f"timeout: no target for {quiet_ns / 1e6:.0f} ms (the stream's timeout is "
                           f"{progress.timeout_ns / 1e6:g} ms)")
        elif quiet_ns > max(progress.timeout_ns, FIRST_TARGET_WAIT_NS):
            self.brake(f"timeout: no first target within {quiet_ns / 1e6:.0f} ms of stream_open (a stream waits "
                       f"{max(progress.timeout_ns, FIRST_TARGET_WAIT_NS) / 1e6:g} ms for its first)")

    def after_step(self) -> None:
        """After this cycle's trajectory update: end once braked to rest."""
        if self.progress is not None and self.progress.phase is StreamPhase.BRAKING and not self._trajectory.moving:
            self.end(self._reason)
