"""The simulated physical platform: where the moving platform really is.

Its structure is a *true* :class:`~hexactl.kinematics.geometry.Geometry` that differs from the
nominal one by manufacturing errors (make one with
:func:`hexactl.sim.true_platform.true_geometry`); its leg lengths are the true zero lengths plus
the simulated actuators' actual (unquantised) positions. The pose follows by forward kinematics,
computed only when asked for (the simulated measuring instrument asks; the physics tick does
not) and warm-started from the previous answer.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from hexactl.kinematics.axes import AbsoluteMmRad, RelativeMmDeg
from hexactl.kinematics.forward import FkStatus, forward_kinematics
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import lengths_from_readings
from hexactl.kinematics.pose import relative_from_absolute



class PoseUnavailable(RuntimeError):
    """Forward kinematics did not converge for the actuators' lengths (a broken simulation or
    lengths no platform of this geometry can have).

    :ivar status: the solver's status
    """

    def __init__(self, status: FkStatus, lengths_mm: Sequence[float]) -> None:
        super().__init__(f"no pose for leg lengths {list(lengths_mm)} mm: forward kinematics {status.name}")
        self.status = status


@dataclass(frozen=True, slots=True)
class TruePose:
    """The platform's true pose.

    :ivar absolute: in the fixed frame, mm and rad (what the instrument measures from)
    :ivar relative: relative to the zero posture, mm and degrees (what people compare)
    :ivar leg_lengths_mm: the true joint-to-joint lengths it was solved from
    """

    absolute: AbsoluteMmRad
    relative: RelativeMmDeg
    leg_lengths_mm: tuple[float, ...]


class PhysicalPlatform:
    """The platform of ``true_geometry`` driven by actuators whose actual positions (sensor
    frame, mm, legs 1–6) ``actual_positions_mm`` returns, e.g.
    :meth:`hexactl.sim.actuator_bus.ActuatorBus.actual_positions_mm`."""

    def __init__(self, true_geometry: Geometry, actual_positions_mm: Callable[[], Sequence[float]]) -> None:
        self.geometry = true_geometry
        self._actual_positions_mm = actual_positions_mm
        self._guess = true_geometry.home.in_radians()

    def leg_lengths_mm(self) -> tuple[float, ...]:
        """True joint-to-joint lengths, mm, of the actuators' actual positions (the sensors'
        readings) by the true geometry's sensor model."""
        return tuple(lengths_from_readings(self.geometry.legs, self._actual_positions_mm()).tolist())

    def true_pose(self, guess: Sequence[float] | None = None) -> TruePose:
        """The pose the actuators' present lengths give (forward kinematics, warm-started
        from ``guess``, absolute mm/rad, or else from the previous answer: a caller asking
        seldom while the platform travels far should pass where it roughly is).

        :raises PoseUnavailable: if forward kinematics does not converge
        """
        lengths = self.leg_lengths_mm()
        result = forward_kinematics(self.geometry.legs, lengths, self._guess if guess is None else guess)
        if not result.ok:
            raise PoseUnavailable(result.status, lengths)
        self._guess = AbsoluteMmRad._make(float(v) for v in result.pose)
        relative = RelativeMmDeg._make(float(v) for v in relative_from_absolute(self.geometry.home, result.pose))
        return TruePose(self._guess, relative, lengths)
