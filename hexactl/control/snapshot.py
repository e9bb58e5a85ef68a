"""What the loop publishes each cycle: its states and an immutable :class:`CoreSnapshot`.

Other threads read the latest snapshot (one reference, swapped once a cycle); the
controller checks its preconditions (:mod:`~hexactl.control.preconditions`) against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from hexactl.control import commands as cmd
from hexactl.control.hardware import FeedbackSnapshot, LinkHealth
from hexactl.control.jog import JogProgress, JogReport
from hexactl.control.planning import ActiveGeometry, LegLock
from hexactl.control.recorder import IDLE, RecorderState
from hexactl.control.sequence_player import SequenceProgress, SequenceReport
from hexactl.control.stream import StreamProgress, StreamReport
from hexactl.control.supervisor import Fault
from hexactl.control.trajectory import KinematicState
from hexactl.control.wave_player import WaveProgress
from hexactl.kinematics.axes import RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames


class ControlState(StrEnum):
    DISABLED = "disabled"
    ENABLED = "enabled"
    FAULT = "fault"
    ESTOP = "estop"


class MotionState(StrEnum):
    HOLDING = "holding"  # at rest on the target (also whenever not ENABLED)
    MOVING = "moving"
    STOPPING = "stopping"  # braking to rest after stop, pause or abort


@dataclass(frozen=True, slots=True)
class Event:
    """Something the loop did or refused, for the log; ``seq`` its number (the loop's
    first event is 1, each next one more: a reader that sees a gap missed events);
    ``t_ns`` monotonic; ``sender`` who sent the command it carried out or refused (None:
    the loop's own doing, or a caller in its own process)."""

    seq: int
    t_ns: int
    code: str
    message: str
    sender: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class CoreSnapshot:
    """What the loop looked like at the end of cycle ``cycle`` (``t_ns`` monotonic).

    Poses relative to the zero posture in mm and rad; ``trajectory`` the generator's
    (position, velocity, acceleration), which a new plan starts from, and ``goal`` its
    target (None while braking; while DISABLED at rest on ``pose_command``, with no goal and
    no frames: where enabling starts the generator), both in the coordinates of ``frames`` (None: relative
    mm/rad; else the tool's pose in the work frame, mm/rad); set-points and
    feedback sensor mm. ``clamped_cycles``: cycles in which the guard changed a
    set-point (each one means a plan was wrong); ``clamped_legs``: bit mask of the
    legs it ever changed.
    """

    t_ns: int
    cycle: int
    state: ControlState
    motion: MotionState
    epoch: int
    pose_command: RelativeMmRad
    trajectory: KinematicState
    goal: RelativeMmRad | ToolInWorkMmRad | None
    frames: Frames | None
    pose_measured: RelativeMmRad | None
    setpoints: tuple[float, ...]
    feedback: FeedbackSnapshot | None
    link: LinkHealth | None
    lock: LegLock | None
    active: ActiveGeometry
    previous: ActiveGeometry | None
    ramp_active: bool
    sequence: SequenceProgress | None
    last_sequence: SequenceReport | None
    faults: tuple[Fault, ...]
    events: tuple[Event, ...]
    outcomes: tuple[cmd.Outcome, ...]
    clamped_cycles: int
    clamped_legs: int
    fk_failures: int
    motion_end_ns: int | None = None  # when the move or braking under way ends as planned; stale while HOLDING
    recorder: RecorderState = IDLE  # the data recorder, as of the end of the cycle before
    jog: JogProgress | None = None  # the jog under way
    last_jog: JogReport | None = None  # how the last jog ended
    wave: WaveProgress | None = None  # the wave playing, or how the last one ended
    stream: StreamProgress | None = None  # the pose stream under way
    last_stream: StreamReport | None = None  # how the last stream ended

    @property
    def target(self) -> RelativeMmRad | ToolInWorkMmRad:
        """Where the motion under way is headed as someone aimed it, in the generator's
        coordinates: a move's or a waypoint's goal; where the platform is at rest, and while
        it jogs (a jog's plan ends at its horizon or on the limit ahead: no one's aim). A
        relative move, and a wave validated under way, start from it."""
        return self.goal if self.goal is not None and self.jog is None else self.trajectory.position
