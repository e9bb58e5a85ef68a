"""The facade's commands of the controller's state: enable, disable, stop, E-stop, reset,
and the leg lock's lock and unlock. Each is checked on the loop's latest snapshot
(:mod:`hexactl.control.preconditions`), then queued for the loop, which checks again."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.config import SupervisionConfig
from hexactl.control.host import LoopHost
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import ControlState, CoreSnapshot, MotionState
from hexactl.control.submitter import CommandSubmitter


def _lock_released(snapshot: CoreSnapshot) -> str:
    """What disabling says of the leg lock it ends: the next enable drives all six legs."""
    lock = snapshot.lock
    return f"; leg {lock.leg} is no longer locked: the next enable drives all six legs" if lock is not None else ""


class StateCommands:
    """The state commands of one facade over ``host``: ``snapshot()`` the loop's latest,
    commands queued by ``submitter``, the actuators supervised as ``supervision`` says."""

    def __init__(self, host: LoopHost, snapshot: Callable[[], CoreSnapshot], submitter: CommandSubmitter,
                 supervision: SupervisionConfig) -> None:
        self._host = host
        self._snapshot = snapshot
        self._submitter = submitter
        self._supervision = supervision

    def enable(self, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.enable`."""
        s = self._snapshot()
        if s.state is ControlState.ENABLED:  # the state asked for: no refusal, as disable's
            return CommandResult.success("already enabled: nothing to do")
        if refusal := preconditions.check_enable(s, self._supervision.heartbeat_timeout_s):
            return CommandResult.failure(*refusal)
        return self._submitter.submit(cmd.Enable, "enabled", deadline_ns=deadline_ns)

    def disable(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.disable`."""
        s = self._snapshot()
        if s.state is ControlState.DISABLED:  # the state asked for: no refusal (as stop's "nothing to stop")
            return CommandResult.success("already disabled: nothing to do")
        return self._submitter.submit_unless(preconditions.check_disable, cmd.Disable, "disabled" + _lock_released(s))

    def stop(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.stop`."""
        s = self._snapshot()
        if s.state is not ControlState.ENABLED:
            message = "nothing to stop: the controller is " + (
                "disabled" if s.state is ControlState.DISABLED else f"in {s.state.name} (reset it to go on)")
        elif s.stream is not None:  # a stream at rest on its target is open all the same: it ends
            message = "stopping: the pose stream ends"
        elif s.motion is MotionState.HOLDING and s.sequence is None:
            message = "nothing to stop: the platform is at rest"
        else:
            message = "stopping"
        return self._submitter.submit(cmd.Stop, message)

    def estop(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.estop`."""
        sent = self._host.estop_now()
        result = self._submitter.submit(cmd.EStop, "E-stop latched")
        if sent is False:
            return CommandResult.failure(ErrorCode.SEND_FAILED, "the E-stop frame could not be sent; the loop "
                                         "latched ESTOP and keeps repeating it", **result.details)
        if sent and result.error is ErrorCode.LOOP_TIMEOUT:
            return replace(result, message=f"E-stop sent to the actuators; the loop's latch of it is {result.message}")
        return result

    def reset(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.reset`."""
        done = self._submitter.submit_unless(preconditions.check_reset, cmd.Reset,
                                             "reset to disabled" + _lock_released(self._snapshot()))
        if not done.ok or done.details.get("pending"):
            return done
        supervision = self._supervision
        if still := self._submitter.settled(lambda s: preconditions.actuator_faulted(s.feedback),
                                            supervision.estop_clear_holdoff_s + supervision.state_timeout_s):
            return replace(done, message=f"{done.message}; {still} still: its cause may remain (a hardware E-stop "
                                         "pressed?), and enable is refused until it clears")
        return done

    def leg_lock(self, leg: int, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.leg_lock`."""
        if isinstance(leg, bool) or not isinstance(leg, (int, np.integer)) or not 1 <= leg <= 6:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, f"leg is a number from 1 to 6, got {leg!r}")
        return self._submitter.submit_unless(preconditions.check_lock, lambda t: cmd.LockLeg(t, int(leg)),
                                             f"leg {leg} locked", deadline_ns=deadline_ns)

    def leg_unlock(self, deadline_ns: int | None) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.leg_unlock`."""
        return self._submitter.submit_unless(preconditions.check_unlock, cmd.UnlockLeg, "unlocked",
                                             deadline_ns=deadline_ns)
