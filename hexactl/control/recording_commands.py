"""The facade's data-recorder commands: start and stop the loop's
:class:`~hexactl.control.recorder.CycleRecorder`. What it records travels back through
the loop's host (:meth:`~hexactl.control.host.LoopHost.take_recorded`); writing it is
the application's (:mod:`hexactl.application.recording`)."""

from __future__ import annotations

from collections.abc import Callable

from hexactl.control import commands as cmd
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import CoreSnapshot
from hexactl.control.submitter import CommandSubmitter


class RecordingCommands:
    """Starts and stops recordings on the loop behind ``submitter``; ``snapshot`` gives
    the loop's latest."""

    def __init__(self, submitter: CommandSubmitter, snapshot: Callable[[], CoreSnapshot]) -> None:
        self._submitter = submitter
        self._snapshot = snapshot

    def start(self, recording: int, name: str, divisor: int, rows: int, on_motion: bool = False) -> CommandResult:
        """Record ``rows`` rows, one every ``divisor`` cycles, as recording ``recording``
        (the id its rows carry), from the next cycle or (``on_motion``) from the next
        motion's first; ``busy`` while another recording is active."""
        for label, value in (("divisor", divisor), ("rows", rows), ("recording", recording)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"{label} is a whole number ≥ 1, got {value!r}")
        state = self._snapshot().recorder
        if state.active:
            return CommandResult.failure(ErrorCode.BUSY, f"recording {state.name!r} is still {state.phase.value}: "
                                         "stop it (record_stop) or wait for it to end")
        return self._submitter.submit(lambda t: cmd.StartRecording(t, recording, name, divisor, rows, on_motion),
                                      "armed: recording from the next motion" if on_motion else "recording")

    def stop(self) -> CommandResult:
        """End the active recording early; ``not_recording`` when none is."""
        if not self._snapshot().recorder.active:
            return CommandResult.failure(ErrorCode.NOT_RECORDING, "no recording is under way: nothing to stop")
        return self._submitter.submit(cmd.StopRecording, "recording stopped")
