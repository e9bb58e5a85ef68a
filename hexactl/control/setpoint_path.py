"""The ENABLED cycle's set-point path: the trajectory's target → the set-points to send.

:meth:`SetpointPath.follow` runs, once a cycle: leg-lock projection of the target
(warm-started from the previous cycle's, a few iterations at most, as planning checked)
→ IK on the active geometry → calibration ramp (:mod:`~hexactl.control.calibration_ramp`)
→ the locked leg held at exactly its locked reading → guard (stroke, velocity limit per
cycle, :func:`~hexactl.control.guard.guard_setpoints`). It keeps the result: the
commanded pose (relative mm/rad, projected in leg-lock mode) and the set-points (sensor
mm), which the core sends, holds in FAULT and publishes.

Owned by the loop thread: not thread-safe.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from hexactl.control.calibration_ramp import CalibrationRamp
from hexactl.control.config import ControllerConfig
from hexactl.control.guard import guard_setpoints
from hexactl.control.hardware import ACTUATOR_COUNT
from hexactl.control.planning import ActiveGeometry, LegLock, track_locked
from hexactl.control.supervisor import Fault
from hexactl.kinematics.axes import RelativeMmRad, ToolInWorkMmRad
from hexactl.kinematics.frames import Frames
from hexactl.kinematics.inverse import sensor_setpoints


class SetpointPath:
    """The commanded pose and set-points of a loop running every ``period_s`` on
    ``active``; ``log(code, message)`` notes the guard's first clamp."""

    def __init__(self, config: ControllerConfig, active: ActiveGeometry, period_s: float,
                 log: Callable[[str, str], None]) -> None:
        self.ramp = CalibrationRamp(config.calibration_ramp_fraction, period_s)
        self._lock_iterations = config.lock_cycle_iterations
        self._period_s = period_s
        self._log = log
        self._max_step_mm = active.geometry.limits.leg_velocity_mm_s * period_s
        # Tuples: published as they are, never changed in place.
        self.pose_command = RelativeMmRad(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self.setpoints: tuple[float, ...] = (0.0,) * ACTUATOR_COUNT
        self.clamped_cycles = 0  # cycles in which the guard changed a set-point
        self.clamped_legs = 0  # bit mask of the legs it ever changed

    def hold(self, pose: Sequence[float], setpoints: Sequence[float]) -> None:
        """Command ``pose`` (relative mm/rad) with ``setpoints`` (sensor mm): where the platform is."""
        self.pose_command = RelativeMmRad._make(pose)
        self.setpoints = tuple(setpoints)

    def swap(self, new: ActiveGeometry, enabled: bool) -> None:
        """``new`` becomes the geometry; ramp the set-points to it when ``enabled`` (when
        not, nothing is being sent and there is nothing to ramp from)."""
        if enabled:
            self.ramp.begin(self.setpoints, new, self.pose_command)
        self._max_step_mm = new.geometry.limits.leg_velocity_mm_s * self._period_s

    def follow(self, active: ActiveGeometry, lock: LegLock | None, target: RelativeMmRad | ToolInWorkMmRad,
               previous_target: RelativeMmRad | None, frames: Frames | None = None) -> Fault | None:
        """This cycle's set-points for the trajectory's ``target``: relative mm/rad, or the
        tool's pose in the work frame of ``frames``; ``previous_target`` last cycle's
        (leg-lock mode only, relative). The fault, with nothing changed, if the leg-lock
        projection fails."""
        if lock is None:
            if frames is None:
                pose, absolute = target, active.absolute_from_relative_mm_rad(target)
            else:
                absolute = frames.platform_pose(target)
                pose = active.relative_from_absolute_mm_rad(absolute)
        else:
            assert previous_target is not None, "leg-lock tracking needs the previous target"
            # pose_command: what last cycle's target was projected to.
            projected = track_locked(active, lock, target, previous_target, self.pose_command, self._lock_iterations)
            if not projected.ok:
                return Fault("leg_lock_projection", f"leg-lock projection failed: {projected.status.name.lower()} "
                             f"after {projected.iterations} iterations", lock.leg)
            pose, absolute = active.relative_from_absolute_mm_rad(projected.pose), projected.pose
        desired = self.ramp.apply(sensor_setpoints(active.geometry.legs, absolute))
        if lock is not None:
            desired[lock.leg - 1] = lock.sensor_mm  # exactly the locked value, not IK's rounding of it
        setpoints, clamped = guard_setpoints(desired, self.setpoints, active.stroke, self._max_step_mm)
        if clamped:
            if not self.clamped_cycles:
                self._log("guard_clamped", f"the set-point guard limited legs mask 0x{clamped:x}: a plan was wrong")
            self.clamped_cycles += 1
            self.clamped_legs |= clamped
        self.setpoints = tuple(setpoints)
        self.pose_command = pose
        return None
