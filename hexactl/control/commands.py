"""Commands from the callers' threads to the loop: immutable objects in a deque.

Producers (the :class:`~hexactl.control.controller.Controller`'s methods, in any
thread) do all parsing, planning and validation first, then ``append`` one of these;
the loop ``popleft``s a bounded number per cycle. ``deque.append``/``popleft`` are
atomic in CPython, so there is no lock the loop could wait on.

``deadline_ns`` (monotonic, None: none) is when the command's sender stops waiting for
it: the loop refuses it as ``expired`` from then on rather than carry out what nobody
waits for any more. The loop and the API's process share the host's monotonic clock.

``sender`` says who sent it, for people (the API's name for its client: the name the
client gave and where it connected from; None: a caller in the loop's own process, or
the loop's own link). The loop's events while it carries the command out name it.

``ticket`` numbers a command; the loop publishes its verdict per ticket
(:class:`Outcome`). ``epoch`` is the loop's plan epoch the command was planned at: the
loop advances it whenever what a plan starts from changes (a new goal, a halt, leg-lock,
a calibration swap), and refuses a plan made at another epoch as stale rather than run
a path nobody validated.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from hexactl.control.jog import JogPlan
from hexactl.control.planning import ActiveGeometry, Segment
from hexactl.control.wave_planning import WavePlan
from hexactl.kinematics.axes import PerAxis, RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames


@dataclass(frozen=True, slots=True)
class Command:
    ticket: int
    deadline_ns: int | None = field(default=None, kw_only=True)
    sender: str | None = field(default=None, kw_only=True)
    answered: ClassVar[bool] = True
    """The loop publishes an :class:`Outcome` for it (a stream's targets: no, they would
    push every other command's verdict out of the kept ones)."""
    brakes: ClassVar[bool] = False
    """It only brings the platform to rest: sent even to a loop that has stopped reporting,
    to be carried out if it runs again (any other command is not sent to it)."""
    superseded: ClassVar[bool] = False
    """The next one of its kind replaces it (a stream's targets): a link that cannot pass it
    on at once may drop it rather than keep it waiting."""

    def event(self) -> tuple[str, str] | None:
        """The event (code, message) the loop records once it has carried this out, when
        carrying it out records none of its own (a jog, a sequence, a stream, an E-stop and
        a calibration swap do)."""
        return None


@dataclass(frozen=True, slots=True)
class Enable(Command):
    def event(self) -> tuple[str, str]:
        return "enabled", "the actuators hold the pose they are at"


@dataclass(frozen=True, slots=True)
class Disable(Command):
    def event(self) -> tuple[str, str]:
        return "disabled", "the actuators are de-energised"


@dataclass(frozen=True, slots=True)
class Stop(Command):
    brakes = True

    def event(self) -> tuple[str, str]:
        return "stop", "any motion under way brakes to rest"


@dataclass(frozen=True, slots=True)
class EStop(Command):
    brakes = True


@dataclass(frozen=True, slots=True)
class Reset(Command):
    def event(self) -> tuple[str, str]:
        return "reset", "fault or E-stop cleared, disabled"


@dataclass(frozen=True, slots=True)
class Move(Command):
    epoch: int
    segment: Segment

    def event(self) -> tuple[str, str]:
        # Where it goes, said: after an incident the log is read for it (found from outside).
        goal = " ".join(f"{value:.3f}" for value in self.segment.goal.in_degrees())
        where = "relative to the zero posture" if self.segment.frames is None else "the tool in the work frame"
        return "move", f"{self.segment.duration_s:.3g} s as planned, to {goal} (mm, deg; {where})"


@dataclass(frozen=True, slots=True)
class FramesSet(Command):
    """The operator's frames and soft limits, which the facade holds, are now ``text``:
    carried out by nothing but its event, so that the loop's log says who changed them."""

    text: str

    def event(self) -> tuple[str, str]:
        return "frames_set", self.text


@dataclass(frozen=True, slots=True)
class LockLeg(Command):
    leg: int

    def event(self) -> tuple[str, str]:
        return "leg_locked", f"leg {self.leg} locked"


@dataclass(frozen=True, slots=True)
class UnlockLeg(Command):
    def event(self) -> tuple[str, str]:
        return "leg_unlocked", "all six legs driven again"


@dataclass(frozen=True, slots=True)
class Play(Command):
    epoch: int
    name: str
    segments: tuple[Segment, ...]


@dataclass(frozen=True, slots=True)
class Pause(Command):
    def event(self) -> tuple[str, str]:
        return "pause", "the sequence pauses"


@dataclass(frozen=True, slots=True)
class Resume(Command):
    """``remainder``: the rest of the interrupted move, planned from where it stopped
    (None when the sequence was paused during a dwell)."""

    epoch: int
    remainder: Segment | None

    def event(self) -> tuple[str, str]:
        return "resume", "the sequence goes on"


@dataclass(frozen=True, slots=True)
class Abort(Command):
    """The sequence or the wave playing ends, braking to rest (its handler records which)."""

    brakes = True


@dataclass(frozen=True, slots=True)
class SwapGeometry(Command):
    """Make ``active`` the loop's geometry: a calibration load, or with ``rollback`` a
    return to the last one in the history (which it must be)."""

    epoch: int
    active: ActiveGeometry
    rollback: bool = False


@dataclass(frozen=True, slots=True)
class Jog(Command):
    """Start a jog (its number: this command's ticket), or re-plan the one under way:
    ``continues`` its number when it goes on as it was (a renewal near the end of its
    plan), which it keeps; refused if that jog has ended meanwhile. ``restarts``: a new
    jog in place of that one, whose deadman lapsed; refused unless its lapse is still
    why it ended (nothing, a stop from anyone, came since)."""

    epoch: int
    plan: JogPlan
    continues: int | None = None
    restarts: int | None = None


@dataclass(frozen=True, slots=True)
class ReleaseJog(Command):
    """The jog under way is released: it brakes to rest (anything else moving goes on: a
    move that took it over is another's)."""

    brakes = True


@dataclass(frozen=True, slots=True)
class RenewJog(Command):
    """Jog ``jog``, under way at ``velocity`` in ``frame`` (as :class:`~hexactl.control.jog.JogPlan`),
    goes on for another deadman interval."""

    jog: int
    frame: str
    velocity: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class StartRecording(Command):
    """Record every ``divisor``-th cycle, ``rows`` rows, as recording ``recording`` (an
    id the reader matches rows by) named ``name``; from the next cycle, or with
    ``on_motion`` from the first cycle of the next motion (:mod:`~hexactl.control.recorder`)."""

    recording: int
    name: str
    divisor: int
    rows: int
    on_motion: bool = False


@dataclass(frozen=True, slots=True)
class StopRecording(Command):
    pass


@dataclass(frozen=True, slots=True)
class PlayWave(Command):
    """Play the validated wave ``plan`` (:mod:`~hexactl.control.wave_planning`)."""

    epoch: int
    plan: WavePlan

    def event(self) -> tuple[str, str]:
        return "wave_started", f"{self.plan.path.duration_s:.3g} s as planned"


@dataclass(frozen=True, slots=True)
class OpenStream(Command):
    """Open a stream (its number: this command's ticket) from ``source`` whose targets
    are in ``frame`` (a :class:`~hexactl.control.frames.Frame` value): the trajectory
    rebased at rest on ``start`` in the coordinates of ``frames`` (None: relative
    mm/rad); the stream ends if no target comes for ``timeout_ns``."""

    epoch: int
    source: str
    frame: str
    frames: Frames | None
    start: RelativeMmRad | ToolInWorkMmRad
    timeout_ns: int


@dataclass(frozen=True, slots=True)
class StreamTarget(Command):
    """Stream ``stream``'s newest target, checked reachable, in the stream's coordinates,
    to pass at ``velocity`` (mm/s, rad/s) in no less than ``horizon_s`` (s; the goal lies that
    far ahead of the sample along its velocity), no axis faster than ``max_velocity``
    (mm/s, rad/s: :func:`~hexactl.control.stream_commands.stream_velocity_limits`), nor
    slower than ``min_velocity`` (None: ``-max_velocity``; a stream being joined, faster
    along its way than against it); ``sequence`` the sender's number, ``received_ns`` when
    it arrived (monotonic)."""

    stream: int
    goal: RelativeMmRad | ToolInWorkMmRad
    velocity: PerAxis
    max_velocity: PerAxis
    horizon_s: float
    sequence: int
    received_ns: int
    min_velocity: PerAxis | None = None
    answered: ClassVar[bool] = False
    superseded: ClassVar[bool] = True


@dataclass(frozen=True, slots=True)
class CloseStream(Command):
    """End the stream under way: brake to rest."""

    def event(self) -> tuple[str, str]:
        return "stream_closed", "the pose stream is closed: braking to rest"


@dataclass(frozen=True, slots=True)
class CommandLinkSilent(Command):
    """Nothing has come from the commands' sender (the API) for ``silent_s`` (s): whatever
    it would send, an E-stop too, may not arrive. A motion under way brakes to rest.
    From the link's own end in the loop's thread, with ticket 0: not answered."""

    silent_s: float
    answered: ClassVar[bool] = False


@dataclass(frozen=True, slots=True)
class CommandLinkHeard(Command):
    """The commands' sender is heard again after ``silent_s`` (s) of silence (ticket 0,
    not answered)."""

    silent_s: float
    answered: ClassVar[bool] = False


DONE = "done"
"""The message of an :class:`Outcome` whose handler said nothing (the submitter's own stands)."""


@dataclass(frozen=True, slots=True)
class CarriedOut:
    """A handler's verdict that it carried its command out, and what it found to do, for
    people: what the loop did can differ from what the submitter's snapshot, a report
    older, led it to expect (a release that finds a jog only the loop has seen start)."""

    message: str


@dataclass(frozen=True, slots=True)
class Outcome:
    """The loop's verdict on command ``ticket``: ``code`` None when carried out, then
    ``message`` is :data:`DONE` or the handler's :class:`CarriedOut` message."""

    ticket: int
    code: str | None
    message: str
