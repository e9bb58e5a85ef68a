"""The control core: commanded poses to actuator set-points at a fixed rate.

ros2_control's split, in modules:

- :mod:`~hexactl.control.hardware` — the hardware interface the CAN link implements
  (:class:`~hexactl.control.hardware.ActuatorInterface`); no wire format here.
- :mod:`~hexactl.control.core` — the controller: one cycle (feedback, FK, commands,
  supervision, trajectory, leg-lock, IK, calibration ramp, guard, send) and the states.
- :mod:`~hexactl.control.loop` — the manager: the real-time thread on absolute deadlines,
  with :mod:`~hexactl.control.realtime` (scheduling, memory, GIL, gc) and
  :mod:`~hexactl.control.stats` (lateness and compute percentiles).
- :mod:`~hexactl.control.controller` — the facade the API calls: validation and planning
  in the caller's thread (:mod:`~hexactl.control.planning`), commands to the loop
  (:mod:`~hexactl.control.commands`) through its host (:mod:`~hexactl.control.host`: the
  loop's thread in this process, or a loop in another process), results
  (:mod:`~hexactl.control.results`) and telemetry.
- Pure pieces: :mod:`~hexactl.control.trajectory` (ruckig in pose space),
  leg-lock projection from :mod:`hexactl.kinematics.leg_lock`,
  :mod:`~hexactl.control.guard` (stroke and velocity limit of every set-point),
  :mod:`~hexactl.control.sequences` (file format, built-ins, dwell records).
"""
