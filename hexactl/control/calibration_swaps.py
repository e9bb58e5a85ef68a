"""The facade's calibration swaps: validate or load a calibrated geometry, or roll back to
the one before, each checked (:mod:`hexactl.control.calibration_checks`) and handed to the
loop, which ramps the set-points to it (:mod:`hexactl.control.calibration_ramp`)."""

from __future__ import annotations

from collections.abc import Callable

from hexactl.control import commands as cmd
from hexactl.control import preconditions
from hexactl.control.calibration_checks import acceptance_refusal, swap_refusal
from hexactl.control.config import ControllerConfig
from hexactl.control.core import KEPT_CALIBRATIONS
from hexactl.control.planning import ActiveGeometry
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.snapshot import ControlState, CoreSnapshot
from hexactl.control.submitter import CommandSubmitter
from hexactl.kinematics.geometry import Geometry


class CalibrationSwaps:
    """Calibration swaps of one facade: ``snapshot()`` the loop's latest, commands queued by
    ``submitter``; a calibration must be acceptable against ``nominal`` (its limits equal
    the hardware's, its parameters plausible) and change no set-point more than
    ``config`` allows."""

    def __init__(self, snapshot: Callable[[], CoreSnapshot], submitter: CommandSubmitter, config: ControllerConfig,
                 nominal: Geometry) -> None:
        self._snapshot = snapshot
        self._submitter = submitter
        self._config = config
        self._nominal = nominal

    def load(self, geometry: Geometry, calibration_id: str, source: str) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.load_calibration`."""
        if not isinstance(geometry, Geometry):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "load_calibration takes a validated Geometry")
        if not isinstance(calibration_id, str) or not calibration_id:
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "the calibration needs a non-empty id")
        new = ActiveGeometry.of(geometry, calibration_id, source)
        if refusal := acceptance_refusal(geometry, f"calibration {calibration_id}", self._nominal):
            return refusal
        if calibration_id == self._snapshot().active.calibration_id:  # nothing to swap, nor to roll back to later
            return CommandResult.success(f"calibration {calibration_id} is already active: nothing changed",
                                         calibration_id=calibration_id, change_mm=0.0,
                                         warnings=geometry.identification_warnings)
        return self._swap(new, f"calibration {calibration_id} loaded")

    def validate(self, geometry: Geometry, calibration_id: str, source: str) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.validate_calibration`."""
        if not isinstance(geometry, Geometry):
            return CommandResult.failure(ErrorCode.INVALID_ARGUMENT, "validate_calibration takes a validated Geometry")
        if refusal := acceptance_refusal(geometry, f"calibration {calibration_id}", self._nominal):
            return refusal
        s, new = self._snapshot(), ActiveGeometry.of(geometry, calibration_id, source)
        checked = self._check(s, new)
        if isinstance(checked, CommandResult):
            return checked
        said, change = _effect(s, new, checked)
        return CommandResult.success(f"calibration {calibration_id} would " + (f"be accepted; {said}" if said else
                                     f"change the set-points by at most {change:.3f} mm"),
                                     calibration_id=calibration_id, change_mm=change,
                                     warnings=geometry.identification_warnings)

    def rollback(self) -> CommandResult:
        """See :meth:`hexactl.control.controller.Controller.rollback_calibration`."""
        s = self._snapshot()
        if s.previous is None:
            # After a restart on a kept calibration the nominal geometry is in no history: say how to get back to it.
            back = ("" if s.active.geometry == self._nominal else "; to go back to the nominal geometry, load its "
                    "file (hexactl load-calibration FILE: the service's --config)")
            return CommandResult.failure(ErrorCode.NO_PREVIOUS_CALIBRATION, "there is no earlier calibration to roll "
                                         f"back to: none is kept before {s.active.calibration_id} (rollbacks return "
                                         f"through the last {KEPT_CALIBRATIONS} in force since start-up){back}")
        return self._swap(s.previous, f"rolled back from calibration {s.active.calibration_id} to "
                          f"{s.previous.calibration_id}", rollback=True)

    def _swap(self, new: ActiveGeometry, message: str, *, rollback: bool = False) -> CommandResult:
        """Check ``new``, then hand it over (with ``rollback``: the last of the history,
        which the loop drops)."""
        s = self._snapshot()
        checked = self._check(s, new)
        if isinstance(checked, CommandResult):
            return checked
        replaced = {"rolled_back_from": s.active.calibration_id} if rollback else {}
        said, change = _effect(s, new, checked)
        return self._submitter.submit(lambda t: cmd.SwapGeometry(t, s.epoch, new, rollback),
                                      message + (f"; {said}" if said else ""),
                                      calibration_id=new.calibration_id, change_mm=change,
                                      warnings=new.geometry.identification_warnings, **replaced)

    def _check(self, s: CoreSnapshot, new: ActiveGeometry) -> float | CommandResult:
        """The largest set-point change swapping in ``new`` makes at ``s``, mm
        (:func:`~hexactl.control.calibration_checks.swap_refusal`), or the refusal. The
        snapshot whose epoch the swap carries: what was checked is what the loop verifies."""
        if refusal := preconditions.check_swap(s, new):
            return CommandResult.failure(*refusal)
        return swap_refusal(s, new, self._config)


def _effect(s: CoreSnapshot, new: ActiveGeometry, change: float) -> tuple[str, float]:
    """What swapping ``new`` in at ``s`` does to the set-points, for the reply: ("",
    ``change``) when enabled (ramped in); else what happens instead, and 0.0. Not enabled,
    the loop sends no set-points or holds those sent (FAULT), and a swap ramps nothing (the
    plan's epoch makes the loop refuse it if the state changes before it gets there)."""
    if s.state is ControlState.ENABLED:
        return "", change
    pose = s.pose_command
    differs = max(abs(a - b) for a, b in zip(new.setpoints_at(pose), s.active.setpoints_at(pose)))
    return (f"nothing is ramped: the controller is {s.state.value}, so no set-point changes (at this pose the new "
            f"calibration puts the legs up to {differs:.3f} mm from where the active one does); the poses shown are "
            "by it from now on, and enabling holds the platform where it is"), 0.0
