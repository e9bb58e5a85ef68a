"""What the API needs of the controller: commands that return a result, and its state.

Poses are relative to the zero posture, mm and deg; times in s. Every command returns
at once (motions run in the control loop) with a :class:`Result`; a refusal carries a
snake_case ``code`` that the API passes through as its error code.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from hexactl.control.sequences import MotionSequence
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import PoseAssessment


class Result(Protocol):
    """The outcome of a command. ``details``: JSON-able, or dataclasses (e.g. workspace
    violations) that :func:`hexactl.adapters.api.commands.jsonable` converts."""

    @property
    def ok(self) -> bool: ...

    @property
    def code(self) -> str | None: ...

    @property
    def message(self) -> str: ...

    @property
    def details(self) -> Any: ...


class ControllerPort(Protocol):
    """The controller as the API drives it. Methods are called from the API thread."""

    @property
    def geometry(self) -> Geometry:
        """The active geometry or calibration."""
        ...

    def enable(self) -> Result: ...

    def disable(self) -> Result: ...

    def stop(self) -> Result: ...

    def estop(self) -> Result: ...

    def reset(self) -> Result: ...

    def move(self, pose: Sequence[float], duration_s: float | None, speed: float | None) -> Result:
        """Start a move; the result's details on a refusal list the violations."""
        ...

    def assess(self, pose: Sequence[float]) -> PoseAssessment:
        """Every limit ``pose`` violates in the current mode, without moving."""
        ...

    def leg_lock(self, leg: int) -> Result: ...

    def leg_unlock(self) -> Result: ...

    def play(self, sequence: MotionSequence) -> Result: ...

    def pause(self) -> Result: ...

    def resume(self) -> Result: ...

    def abort(self) -> Result: ...

    def load_calibration(self, geometry: Geometry) -> Result: ...

    def rollback_calibration(self) -> Result: ...

    def telemetry(self) -> dict[str, Any]:
        """The current state as a :class:`~hexactl.adapters.api.messages.Telemetry` record."""
        ...
