"""Projection of a pose onto a locked leg's constraint surface: the calibration's name for it.

With leg i locked at length L_i the platform keeps five degrees of freedom, the poses with
‖T·P_mi + R − B_i‖ = L_i. Leg-lock planning samples poses and projects them onto that
surface; the controller's leg-lock mode projects every target the same way. There is one
implementation, shared by both: :func:`hexactl.control.leg_lock.project_to_locked_leg`
(plain-float Python, pure, never raises, status codes; the closest pose in the metric
|δposition|² + c²·|δangles|², c = ``Geometry.characteristic_length_mm``, to 1e-9 mm). It
lives with the control loop because that is where its speed matters; it depends on the
kinematics only, so importing it keeps this package pure.
"""

from hexactl.control.leg_lock import (
    PROJECTION_MAX_ITERATIONS,
    PROJECTION_TOLERANCE_MM,
    ProjectionResult,
    ProjectionStatus,
    project_to_locked_leg,
)

__all__ = [
    "PROJECTION_MAX_ITERATIONS",
    "PROJECTION_TOLERANCE_MM",
    "ProjectionResult",
    "ProjectionStatus",
    "project_to_locked_leg",
]
