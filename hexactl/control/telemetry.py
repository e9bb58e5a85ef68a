"""What the controller reports: ``status`` and each cycle's telemetry, built from the
loop's latest report (:class:`~hexactl.control.host.LoopReport`). Poses relative to the
zero posture, mm and degrees; legs in actuator sensor mm."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from math import isfinite

from hexactl.control.core import CoreSnapshot, Fault, MotionState
from hexactl.control.host import LoopReport
from hexactl.control.jog import JogReport
from hexactl.control.realtime import RealtimeReport
from hexactl.control.results import CommandResult
from hexactl.control.stats import LoopStats
from hexactl.control.stream import StreamReport
from hexactl.control.snapshot import Event
from hexactl.control.frames import OperatorFrames, convert
from hexactl.control.wave_player import WaveProgress
from hexactl.kinematics.axes import RelativeMmDeg, ToolInWorkMmDeg

PERCENTILES_MAX_AGE_S = 0.25
"""Status and telemetry recompute the loop's percentiles (a sort of its window) at most this often."""

TELEMETRY_EVENTS = 8
"""The loop's latest events in each telemetry record: enough that a display that skips
records (telemetry is conflated) still sees a burst of them (an E-stop's fault and its
reset), few enough not to double a record's size."""


@dataclass(frozen=True, slots=True)
class SequenceTelemetry:
    """The playing sequence: ``index`` 1-based waypoint being approached or dwelt at."""

    name: str
    index: int
    total: int
    phase: str


@dataclass(frozen=True, slots=True)
class RecordingTelemetry:
    """The data recorder: ``state`` idle, armed, recording or done (``ended``: duration
    or stopped); ``rows`` recorded of ``rows_requested``; ``lost`` for want of room."""

    state: str
    name: str
    rows: int
    rows_requested: int
    lost: int
    ended: str | None


@dataclass(frozen=True, slots=True)
class JogTelemetry:
    """The jog under way: ``jog`` its number; ``velocity`` (mm/s, deg/s) in ``frame`` as
    requested, run at ``speed`` of it; ``phase`` jogging, at_end or braking; ``end`` where
    its plan ends (``to_limit``: on a limit, else at the horizon a renewal extends);
    ``renew_within_s``: time left before the deadman lapses, s."""

    jog: int
    frame: str
    velocity: tuple[float, ...]
    speed: float
    phase: str
    end: str
    to_limit: bool
    renew_within_s: float


@dataclass(frozen=True, slots=True)
class StreamTelemetry:
    """The pose stream under way: ``stream`` its number, ``source`` as its client named
    it, poses in ``frame``, ``phase`` following or braking (to its end), ``timeout_s`` its
    deadman; ``targets`` the loop took, the newest numbered ``last_sequence`` by its
    sender, taken ``since_target_s`` ago, ``latency_ms`` after its arrival in the API's
    process (None before the first)."""

    stream: int
    source: str
    frame: str
    phase: str
    timeout_s: float
    targets: int
    last_sequence: int | None
    since_target_s: float
    latency_ms: float | None


@dataclass(frozen=True, slots=True)
class LegStatus:
    """One actuator as it last reported: ``state`` disabled, enabled, locked, fault or
    estop; ``fault_bits`` its drive's fault word (0: none) and ``fault_names`` its set
    bits' names, lowest first (``sensor``; ``bit_N`` for one the protocol does not
    define); ``report_age_s`` since its last report, s (None: never heard from)."""

    state: str
    fault_bits: int
    fault_names: tuple[str, ...]
    report_age_s: float | None


@dataclass(frozen=True, slots=True)
class SequenceEnd:
    """The sequence playing or the last one: ``status`` playing, finished, aborted or
    fault; ``records`` the dwell records it took (its waypoints done)."""

    name: str
    status: str
    records: int


@dataclass(frozen=True, slots=True)
class OtherController:
    """Another controller heard on the bus, driving the same actuators: ``frame`` the kind
    of its last frame heard in the protocol's words (``SYNC``, ``CMD_3 ENABLE``), ``age_s``
    how long ago, s; within :data:`~hexactl.control.results.OTHER_CONTROLLER_WINDOW_S`
    ``enable`` is refused."""

    frame: str
    age_s: float


@dataclass(frozen=True, slots=True)
class LinkTelemetry:
    """The link to the actuators: ``bus_state`` in CAN's error-state terms (active,
    warning, passive, bus_off, down); ``send_failures`` frames it could not send since
    it was opened; ``detail`` its note for people (silent legs, a leg restarted, the last
    driver error), empty when it has none."""

    bus_state: str
    send_failures: int
    detail: str


@dataclass(frozen=True, slots=True)
class EventTelemetry:
    """One of the loop's events: ``seq`` its number (one more than the one before), at
    ``t`` (s, the clock of :attr:`Telemetry.t`), ``code`` (snake_case) and ``message``
    for people; ``sender`` who sent the command it carried out or refused, as the API
    names its client (None: the loop's own doing)."""

    seq: int
    t: float
    code: str
    message: str
    sender: str | None


@dataclass(frozen=True, slots=True)
class Telemetry:
    """One cycle's picture. ``t``: monotonic time of the cycle, s. Poses relative to the
    zero posture, mm and deg (``pose_measured`` None when the feedback has no FK
    solution). Legs in sensor mm; an actuator not heard from yet reads NaN in
    ``leg_feedback`` (and, while DISABLED, in ``leg_setpoints``, which then mirror the
    feedback); ``leg_feedback`` is None before the first read. ``goal``: where the move
    under way ends, relative mm and deg (None at rest and while braking); ``remaining_s``:
    time until the move or the braking under way ends as planned, s (None at rest);
    ``tool_pose_command``, ``tool_pose_measured``: the poses as the tool's in the work
    frame of ``frames`` (the operator's), mm and deg."""

    t: float
    state: str
    motion: str
    pose_command: RelativeMmDeg
    pose_measured: RelativeMmDeg | None
    leg_setpoints: tuple[float, ...]
    leg_feedback: tuple[float, ...] | None
    locked_leg: int | None
    calibration_id: str
    sequence: SequenceTelemetry | None
    faults: tuple[Fault, ...]
    loop: LoopStats
    last_sequence: SequenceEnd | None = None  # the sequence playing or the last one; None: none since the start
    realtime: RealtimeReport | None = None  # what the loop thread's real-time set-up obtained
    goal: RelativeMmDeg | None = None
    remaining_s: float | None = None
    tool_pose_command: ToolInWorkMmDeg | None = None
    tool_pose_measured: ToolInWorkMmDeg | None = None
    frames: OperatorFrames | None = None
    outside_soft_limits: tuple[str, ...] = ()  # the soft limits the commanded pose breaks, one sentence each
    recording: RecordingTelemetry | None = None  # None: no recording since the start
    jog: JogTelemetry | None = None  # None: no jog under way
    last_jog: JogReport | None = None  # how the last jog ended; None: none since the start
    wave: WaveProgress | None = None  # the wave playing, or how the last one ended; None: no wave since the start
    stream: StreamTelemetry | None = None  # None: no pose stream under way
    last_stream: StreamReport | None = None  # how the last pose stream ended; None: none since the start
    legs: tuple[LegStatus, ...] | None = None  # None before the first read
    events: tuple[EventTelemetry, ...] = ()  # the loop's latest (TELEMETRY_EVENTS), oldest first
    other_controller: OtherController | None = None  # None: none heard since the loop started
    link: LinkTelemetry | None = None  # None before the first read


def sequence_end(s: CoreSnapshot) -> SequenceEnd | None:
    """The sequence playing or how the last one ended (None: none since the start)."""
    last = s.last_sequence
    return SequenceEnd(last.name, last.status, len(last.records)) if last else None


def leg_statuses(s: CoreSnapshot) -> tuple[LegStatus, ...] | None:
    """Each actuator's last report (None before the first read)."""
    if s.feedback is None:
        return None
    return tuple(LegStatus(a.state.name.lower(), a.fault_bits, a.fault_names,
                           a.heartbeat_age_s if isfinite(a.heartbeat_age_s) else None)
                 for a in s.feedback.actuators)


def other_controller(s: CoreSnapshot) -> OtherController | None:
    """The last other controller the link heard (None: none since the loop started)."""
    link = s.link
    if link is None or not isfinite(link.other_controller_age_s):
        return None
    return OtherController(link.other_controller_frame, link.other_controller_age_s)


def link_telemetry(s: CoreSnapshot) -> LinkTelemetry | None:
    """The link's health as the loop last read it (None before the first read)."""
    link = s.link
    return None if link is None else LinkTelemetry(link.bus_state.value, link.send_failures, link.detail)


def status_result(report: LoopReport, frames: OperatorFrames) -> CommandResult:
    """``status``: state, calibration, sequence, faults, the last ten events, the loop's
    health, the operator's ``frames``, another controller heard on the bus and the link's health."""
    s = report.snapshot
    return CommandResult.success(
        s.state.value,
        state=s.state.value,
        motion=s.motion.value,
        locked_leg=s.lock.leg if s.lock else None,
        calibration_id=s.active.calibration_id,
        calibration_source=s.active.source,
        previous_calibration_id=s.previous.calibration_id if s.previous else None,
        calibration_ramping=s.ramp_active,
        sequence=asdict(sequence_telemetry(s)) if s.sequence else None,
        last_sequence=asdict(end) if (end := sequence_end(s)) else None,
        faults=[asdict(f) for f in s.faults],
        events=[asdict(e) for e in s.events[-10:]],
        loop_running=report.running,
        loop_failure=report.failure,
        realtime=asdict(report.realtime) if report.realtime else None,
        frames=frames.model_dump(mode="json"),
        recording=asdict(recording) if (recording := recording_telemetry(s)) else None,
        jog=asdict(jog) if (jog := jog_telemetry(s)) else None,
        last_jog=asdict(s.last_jog) if s.last_jog else None,
        wave=asdict(s.wave) if s.wave else None,
        stream=asdict(stream) if (stream := stream_telemetry(s)) else None,
        last_stream=asdict(s.last_stream) if s.last_stream else None,
        other_controller=asdict(other) if (other := other_controller(s)) else None,
        link=asdict(link) if (link := link_telemetry(s)) else None,
    )


def telemetry_of(report: LoopReport, frames: OperatorFrames) -> Telemetry:
    """The report's cycle as telemetry, its poses also as the tool's in the work frame of
    the operator's ``frames``; the core's guard clamps and FK failures join the loop's
    statistics."""
    s = report.snapshot
    home = s.active.home
    in_work = frames.frames(home)
    moving_to = s.goal if s.motion is MotionState.MOVING else None
    stats = replace(report.stats, guard_clamps=s.clamped_cycles, fk_failures=s.fk_failures)
    return Telemetry(
        t=s.t_ns / 1e9,
        state=s.state.value,
        motion=s.motion.value,
        pose_command=s.pose_command.in_degrees(),
        pose_measured=s.pose_measured.in_degrees() if s.pose_measured is not None else None,
        leg_setpoints=s.setpoints,
        leg_feedback=s.feedback.positions_mm if s.feedback else None,
        locked_leg=s.lock.leg if s.lock else None,
        calibration_id=s.active.calibration_id,
        sequence=sequence_telemetry(s),
        faults=s.faults,
        loop=stats,
        last_sequence=sequence_end(s),
        realtime=report.realtime,
        goal=None if moving_to is None else convert(moving_to, s.frames, None, home).in_degrees(),
        remaining_s=motion_remaining_s(s),
        tool_pose_command=(tool_command := convert(s.pose_command, None, in_work, home).in_degrees()),
        tool_pose_measured=None if s.pose_measured is None
        else convert(s.pose_measured, None, in_work, home).in_degrees(),
        frames=frames,
        outside_soft_limits=() if frames.soft_limits.allow(tool_command)  # plain floats first: every record asks
        else tuple(v.message for v in frames.soft_limits.violations([tool_command])[0]),
        recording=recording_telemetry(s),
        jog=jog_telemetry(s),
        last_jog=s.last_jog,
        wave=s.wave,
        stream=stream_telemetry(s),
        last_stream=s.last_stream,
        legs=leg_statuses(s),
        events=tuple(event_telemetry(e) for e in s.events[-TELEMETRY_EVENTS:]),
        other_controller=other_controller(s),
        link=link_telemetry(s),
    )


def event_telemetry(e: Event) -> EventTelemetry:
    return EventTelemetry(e.seq, e.t_ns / 1e9, e.code, e.message, e.sender)


@dataclass(frozen=True, slots=True)
class EventLog:
    """The loop's kept events numbered after ``after`` (a reader's last seen), oldest
    first, as the snapshot taken at ``t`` (s, the clock of :attr:`Telemetry.t`) had them.
    ``missed``: how many came after ``after`` that the loop no longer keeps; ``last``: the
    newest event's number (0: none yet; less than ``after``: the loop has restarted since)."""

    t: float
    events: tuple[EventTelemetry, ...]
    missed: int
    last: int


def events_after(kept: tuple[Event, ...], t_ns: int, after: int) -> EventLog:
    """The events ``kept`` at ``t_ns`` (the loop's clock) numbered after ``after`` (see
    :class:`EventLog`)."""
    newer = tuple(event_telemetry(e) for e in kept if e.seq > after)
    return EventLog(t_ns / 1e9, newer, newer[0].seq - after - 1 if newer else 0, kept[-1].seq if kept else 0)


def recording_telemetry(s: CoreSnapshot) -> RecordingTelemetry | None:
    """The data recorder's state (None: no recording since the start)."""
    r = s.recorder
    if r.recording == 0:
        return None
    return RecordingTelemetry(r.phase.value, r.name, r.rows, r.rows_requested, r.lost,
                              r.ended.value if r.ended else None)


def motion_remaining_s(s: CoreSnapshot) -> float | None:
    """Time until the motion under way ends as planned, s; None at rest."""
    if s.motion is MotionState.HOLDING or s.motion_end_ns is None:
        return None
    return max(0.0, (s.motion_end_ns - s.t_ns) / 1e9)


def sequence_telemetry(s: CoreSnapshot) -> SequenceTelemetry | None:
    """The playing sequence's progress (None: none playing)."""
    p = s.sequence
    return SequenceTelemetry(p.name, p.waypoint, p.total, p.phase.value) if p else None


def jog_telemetry(s: CoreSnapshot) -> JogTelemetry | None:
    jog = s.jog
    if jog is None:
        return None
    return JogTelemetry(jog.jog, jog.frame, jog.velocity, jog.speed, jog.phase.value, jog.end, jog.to_limit,
                        max(0.0, (jog.deadline_ns - s.t_ns) / 1e9))


def stream_telemetry(s: CoreSnapshot) -> StreamTelemetry | None:
    stream = s.stream
    if stream is None:
        return None
    return StreamTelemetry(stream.stream, stream.source, stream.frame, stream.phase.value, stream.timeout_ns / 1e9,
                           stream.targets, stream.last_sequence, max(0.0, (s.t_ns - stream.last_target_ns) / 1e9),
                           None if stream.latency_ns is None else stream.latency_ns / 1e6)
