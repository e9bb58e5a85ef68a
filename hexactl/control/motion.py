"""What the platform is told to do: the trajectory, the leg lock, the sequence, the plan epoch.

:class:`Motion` owns the loop's online trajectory generator
(:class:`~hexactl.control.trajectory.PoseTrajectory`), the set-point path it feeds
(:class:`~hexactl.control.setpoint_path.SetpointPath`), the sequence player
(:class:`~hexactl.control.sequence_player.SequencePlayer`), the wave player
(:class:`~hexactl.control.wave_player.WavePlayer`: while a wave plays it, not the
generator's update, gives each cycle's position), a pose stream's follower
(:class:`~hexactl.control.stream.StreamFollower`) and the locked leg. Its
:meth:`Motion.update` is the ENABLED cycle's update: the trajectory's next target →
the set-points → playback.

The plan epoch (:mod:`hexactl.control.commands`) advances whenever what a plan starts
from changes: a new goal, a halt, a pause or resume, leg-lock, a calibration swap, a
freeze. The core checks each command's preconditions
(:mod:`~hexactl.control.preconditions`) before calling the method that carries it out.

Poses relative mm/rad; set-points sensor mm; times monotonic ns. Owned by the loop
thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from hexactl.control.config import ControllerConfig
from hexactl.control.jog import Jogger, JogPhase, JogPlan
from hexactl.control.planning import ActiveGeometry, LegLock, Segment
from hexactl.control.preconditions import Refusal
from hexactl.control.results import JOG_RELEASED, ErrorCode
from hexactl.control.sequence_player import SequencePhase, SequencePlayer, start_segment
from hexactl.control.sequences import DwellRecord
from hexactl.control.setpoint_path import SetpointPath
from hexactl.control.snapshot import MotionState
from hexactl.control.stream import StreamFollower
from hexactl.control.supervisor import Fault
from hexactl.control.trajectory import PoseTrajectory, StepResult
from hexactl.control.wave_planning import WavePlan
from hexactl.control.wave_player import WavePhase, WavePlayer
from hexactl.kinematics.axes import RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames


class Motion:
    """The motion of a loop running every ``period_s`` on ``active``. ``record`` and
    ``log`` as :class:`~hexactl.control.sequence_player.SequencePlayer`'s."""

    def __init__(self, config: ControllerConfig, active: ActiveGeometry, period_s: float,
                 record: Callable[[str, int], DwellRecord], log: Callable[[str, str], None]) -> None:
        self.trajectory = PoseTrajectory(config.motion, period_s)
        self.path = SetpointPath(config, active, period_s, log)
        self.player = SequencePlayer(self.trajectory, record, log)
        self.jogger = Jogger(self.trajectory, log)
        self.wave = WavePlayer(self.trajectory, log)
        self.stream = StreamFollower(self.trajectory, config.stream, log)
        self.lock: LegLock | None = None
        self.epoch = 0
        self.end_ns: int | None = None
        """When the trajectory's move or halt is planned to end (monotonic ns); stale once it is at rest."""

    def state(self, enabled: bool) -> MotionState:
        trajectory = self.trajectory
        if not enabled or not trajectory.moving:
            return MotionState.HOLDING
        return MotionState.STOPPING if trajectory.halting else MotionState.MOVING

    @property
    def under_way(self) -> bool:
        """Whether the platform moves or will move by itself: a move, a halt, a sequence
        (not paused), a wave, a jog or a stream."""
        sequence = self.player.progress
        return (self.trajectory.moving or self.wave.playing or self.jogger.progress is not None
                or self.stream.progress is not None
                or (sequence is not None and sequence.phase is not SequencePhase.PAUSED))

    def stale(self, epoch: int) -> Refusal:
        """The refusal of a command planned at ``epoch`` if that is not the current one."""
        if epoch != self.epoch:
            # Not "plan again": what came first may be a stop, which a blind retry would undo.
            return ErrorCode.STALE_PLAN, ("the motion changed while the command was being planned (a stop, another "
                                          "motion or a calibration swap came first): not carried out; look at what "
                                          "came (hexactl events) before sending it again")
        return None

    # -- the cycle ---------------------------------------------------------------------

    def update(self, active: ActiveGeometry, now_ns: int) -> Fault | None:
        """The ENABLED cycle: the next target → set-points (not yet sent) → playback; the
        fault if the generator or the leg-lock projection fails (nothing then changed)."""
        trajectory = self.trajectory
        lock = self.lock
        previous_target = trajectory.position if lock is not None else None
        jogger = self.jogger
        if jogger.progress is not None:
            jogger.before_step(now_ns)
        stream = self.stream
        if stream.progress is not None:
            stream.before_step(now_ns)
        wave = self.wave
        result = wave.update() if wave.playing else trajectory.update()  # a wave drives the generator's state
        if jogger.progress is not None:
            jogger.after_step()
        if stream.progress is not None:
            stream.after_step()
        if result is StepResult.ERROR:
            return Fault("planner_error", "the trajectory generator refused its input")
        if result is StepResult.WORKING and trajectory.replanned and not wave.playing:
            self.end_ns = now_ns + round(trajectory.remaining_s * 1e9)
        if wave.brake_started:  # a stopped wave brakes along its path: its rest is this far ahead
            wave.brake_started = False
            self.end_ns = now_ns + round(wave.remaining_s * 1e9)
        if fault := self.path.follow(active, lock, trajectory.position, previous_target, trajectory.frames):
            return fault
        if self.player.playing:
            self.player.update(result, now_ns)
        return None

    def start(self, pose: Sequence[float], setpoints: Sequence[float]) -> None:
        """Enabled at rest at ``pose`` with ``setpoints``: where the platform is."""
        self.path.hold(pose, setpoints)
        self.trajectory.rebase(pose, None)
        self.epoch += 1

    def follow(self, pose: Sequence[float], setpoints: Sequence[float]) -> None:
        """While disabled: command where the platform is, so that enabling starts there."""
        self.path.hold(pose, setpoints)

    def freeze(self, sequence_status: str, why: str) -> None:
        """Forget any motion (the sequence ends as ``sequence_status``, a stream saying
        ``why``): the commanded pose and set-points stay as they are."""
        self.trajectory.rebase(self.path.pose_command, None)
        self.path.ramp.cancel()
        self.player.end(sequence_status)
        self.jogger.end(sequence_status)
        self.wave.end(WavePhase.FAULT if sequence_status == "fault" else WavePhase.ABORTED)
        self.stream.end(why)
        self.epoch += 1

    # -- commands, once their preconditions hold -----------------------------------------

    def move(self, segment: Segment) -> Refusal:
        if not start_segment(self.trajectory, segment):
            return ErrorCode.STALE_PLAN, ("the motion went on while the move was planned, and from where it is now the "
                                          "trajectory generator refuses it: plan again")
        self.wave.end(WavePhase.ABORTED)  # a stopped wave's brake, replaced (its phase stays ABORTED)
        self.jogger.end("replaced by a move")
        return None

    def jog(self, jog: int, plan: JogPlan, now_ns: int) -> Refusal:
        """Start jog ``jog`` (or re-plan the one under way) with ``plan``."""
        if not start_segment(self.trajectory, plan.segment):
            return ErrorCode.STALE_PLAN, ("the motion went on while the jog was planned, and from where it is now the "
                                          "trajectory generator refuses it: send jog again")
        self.wave.end(WavePhase.ABORTED)  # as in move
        self.jogger.start(jog, plan, now_ns)
        return None

    def play(self, name: str, segments: tuple[Segment, ...]) -> None:
        self.jogger.end("replaced by a sequence")
        self.player.play(name, segments)

    def play_wave(self, plan: WavePlan, now_ns: int) -> None:
        """Play the wave of ``plan`` (from rest, where it was planned)."""
        self.jogger.end("replaced by a wave")
        self.wave.play(plan)
        self.end_ns = now_ns + round(plan.path.duration_s * 1e9)
        self.epoch += 1

    def stop(self) -> None:
        """Abort any sequence or wave and brake to rest: a wave along its own path (it has
        no goal, and a per-axis brake would leave the path it was validated on), anything
        else by the generator's halt."""
        self.player.end("aborted")
        if self.wave.playing:
            self.wave.brake()  # ABORTED now; at rest on the path (a second stop: the brake goes on)
        else:
            self.trajectory.halt(self.stream.braking_limits)
        self.jogger.brake("stopped")
        self.stream.brake("stopped")
        self.epoch += 1

    def release_jog(self) -> bool:
        """Brake the jog under way to rest, as released; False if none is (at rest, braking
        or taken over)."""
        progress = self.jogger.progress
        if progress is None or progress.phase is JogPhase.BRAKING:
            return False
        self.trajectory.halt()
        self.jogger.brake(JOG_RELEASED)
        self.epoch += 1
        return True

    def open_stream(self, stream: int, source: str, frame: str, frames: Frames | None,
                    start: RelativeMmRad | ToolInWorkMmRad, timeout_ns: int, now_ns: int) -> None:
        """Open stream ``stream`` (from rest): the generator rebased at rest on ``start`` in
        the coordinates of ``frames``; see :class:`~hexactl.control.commands.OpenStream`."""
        self.jogger.end("replaced by a stream")
        self.trajectory.rebase(start, frames)
        self.stream.start(stream, source, frame, timeout_ns, now_ns)
        self.epoch += 1

    def close_stream(self) -> None:
        """Brake to rest, then the stream ends."""
        self.trajectory.halt(self.stream.braking_limits)
        self.stream.brake("closed by the client")
        self.epoch += 1

    def lock_leg(self, leg: int) -> None:
        """Hold leg 1–6 at the set-point being sent; the motion (at rest) continues in
        relative coordinates, which leg-lock tracking works in."""
        self.jogger.end("a leg was locked")
        self.lock = LegLock(leg, self.path.setpoints[leg - 1])
        self.trajectory.rebase(self.path.pose_command, None)
        self.epoch += 1

    def unlock_leg(self) -> None:
        self.lock = None
        # Bumpless: the projected pose being commanded becomes the generator's state.
        self.trajectory.rebase(self.path.pose_command, None)
        self.epoch += 1

    def pause(self, now_ns: int) -> None:
        self.player.pause(now_ns)
        self.epoch += 1

    def resume(self, remainder: Segment | None, now_ns: int) -> Refusal:
        if refusal := self.player.resume(remainder, now_ns):
            return refusal
        self.epoch += 1
        return None

    def swap(self, new: ActiveGeometry, enabled: bool) -> None:
        """``new`` is the geometry from now on (ramped in when ``enabled``)."""
        self.path.swap(new, enabled)
        if self.jogger.progress is not None:  # its limits were found on the old geometry
            self.trajectory.halt()
            self.jogger.brake("the calibration changed")
        self.epoch += 1
