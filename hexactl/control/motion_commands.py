"""The motion's commands in the loop: each one's preconditions, then the motion carries it out.

A part of :class:`~hexactl.control.core.ControlCore`: the loop's inbox hands these
handlers the commands that start, change or end a motion (moves, jogs, sequences, waves).
Each checks its preconditions (:mod:`~hexactl.control.preconditions`) on the core's view
and that it was planned at the current plan epoch, then calls
:class:`~hexactl.control.motion.Motion`. Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.command_inbox import Handler
from hexactl.control.jog import restartable
from hexactl.control.motion import Motion
from hexactl.control.preconditions import CoreView, Refusal
from hexactl.control.results import ErrorCode
from hexactl.control.snapshot import ControlState, MotionState


class MotionCommands:
    """The handlers of the motion's commands for ``motion``, checked on ``view`` (the core);
    ``now_ns()`` is the cycle's monotonic time; ``log(code, message)`` notes an event."""

    def __init__(self, view: CoreView, motion: Motion, now_ns: Callable[[], int],
                 log: Callable[[str, str], None]) -> None:
        self._view = view
        self._motion = motion
        self._now_ns = now_ns
        self._log = log

    def handlers(self) -> dict[type[cmd.Command], Handler]:
        return {cmd.Move: self._move, cmd.Jog: self._jog, cmd.RenewJog: self._renew_jog,
                cmd.ReleaseJog: self._release_jog, cmd.Stop: self._stop,
                cmd.Play: self._play, cmd.PlayWave: self._play_wave, cmd.Pause: self._pause, cmd.Resume: self._resume,
                cmd.Abort: self._abort, cmd.OpenStream: self._open_stream, cmd.StreamTarget: self._stream_target,
                cmd.CloseStream: self._close_stream, cmd.CommandLinkSilent: self._command_link_silent,
                cmd.CommandLinkHeard: self._command_link_heard}

    def _move(self, command: cmd.Move) -> Refusal:
        return preconditions.check_move(self._view) or self._motion.stale(command.epoch) or self._motion.move(command.segment)

    def _jog(self, command: cmd.Jog) -> Refusal:
        continues = command.continues  # a jog planned on keeps its number, and must still be under way
        number = command.ticket if continues is None else continues
        return (preconditions.check_jog(self._view)
                or (self._motion.jogger.ended(continues) if continues is not None else None)
                or self._not_restartable(command.restarts)
                or self._motion.stale(command.epoch) or self._motion.jog(number, command.plan, self._now_ns()))

    def _not_restartable(self, jog: int | None) -> Refusal:
        """Why jog ``jog`` is not to be restarted: it ended otherwise than by its lapse, or
        something came after (None: it may be, it is still under way, or none is to be)."""
        jogger = self._motion.jogger
        if jog is None or restartable(jogger.progress, jogger.report, jog):
            return None
        return jogger.ended(jog)

    def _renew_jog(self, command: cmd.RenewJog) -> Refusal:
        return self._motion.jogger.renew(command.jog, command.frame, command.velocity, self._now_ns())

    def _release_jog(self, command: cmd.ReleaseJog) -> cmd.CarriedOut:
        jog = self._motion.jogger.progress
        at_rest = self._view.motion is MotionState.HOLDING
        if not self._motion.release_jog():
            return cmd.CarriedOut("nothing to release: no jog is under way")
        message = f"jog {jog.jog} released" + (" (at rest)" if at_rest else ": braking to rest")
        self._log("jog_released", message)
        return cmd.CarriedOut(message)

    def _stop(self, command: cmd.Stop) -> Refusal:
        self._motion.stop()
        return None

    def _command_link_silent(self, command: cmd.CommandLinkSilent) -> Refusal:
        # Brake rather than latch a FAULT: the platform comes to rest on its trajectory
        # instead of the drives' own deceleration, and stays enabled for when the API is back.
        braking = self._view.state is ControlState.ENABLED and self._motion.under_way
        if braking:
            self._motion.stop()
        self._log("command_link_silent", (
            f"nothing from the API for {command.silent_s:.1f} s (its process frozen or starved of CPU): "
            + ("the motion is braked to rest; " if braking else "nothing was moving; ")
            + "an E-stop sent through the API may not arrive now: use the hardware E-stop"))
        return None

    def _command_link_heard(self, command: cmd.CommandLinkHeard) -> Refusal:
        self._log("command_link_heard", f"the API is heard again after {command.silent_s:.1f} s of silence")
        return None

    def _play(self, command: cmd.Play) -> Refusal:
        if refusal := preconditions.check_play(self._view) or self._motion.stale(command.epoch):
            return refusal
        self._motion.play(command.name, command.segments)
        return None

    def _play_wave(self, command: cmd.PlayWave) -> Refusal:
        if refusal := preconditions.check_wave(self._view) or self._motion.stale(command.epoch):
            return refusal
        self._motion.play_wave(command.plan, self._now_ns())
        return None

    def _pause(self, command: cmd.Pause) -> Refusal:
        if refusal := preconditions.check_pause(self._view):
            return refusal
        self._motion.pause(self._now_ns())
        return None

    def _resume(self, command: cmd.Resume) -> Refusal:
        return (preconditions.check_resume(self._view) or self._motion.stale(command.epoch)
                or self._motion.resume(command.remainder, self._now_ns()))

    def _open_stream(self, command: cmd.OpenStream) -> Refusal:
        if refusal := preconditions.check_stream(self._view) or self._motion.stale(command.epoch):
            return refusal
        self._motion.open_stream(command.ticket, command.source, command.frame, command.frames, command.start,
                                 command.timeout_ns, self._now_ns())
        return None

    def _stream_target(self, command: cmd.StreamTarget) -> Refusal:
        self._motion.stream.target(command.stream, command.goal, command.velocity, command.max_velocity,
                                   command.horizon_s, command.sequence, command.received_ns, self._now_ns(),
                                   command.min_velocity)
        return None

    def _close_stream(self, command: cmd.CloseStream) -> Refusal:
        if not self._motion.stream.open:
            return ErrorCode.NO_STREAM, "no stream is open"
        self._motion.close_stream()
        return None

    def _abort(self, command: cmd.Abort) -> Refusal:
        if refusal := preconditions.check_abort(self._view):
            return refusal
        ended = "the sequence ends, braking to rest" if self._view.sequence is not None else \
            "the wave ends, braking to rest on its path"
        self._motion.stop()
        self._log("abort", ended)
        return None
