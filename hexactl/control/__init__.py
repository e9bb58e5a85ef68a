"""The control core: commanded poses to actuator set-points at a fixed rate.

ros2_control's split, in modules:

- :mod:`~hexactl.control.hardware` — the hardware interface the CAN link implements
  (:class:`~hexactl.control.hardware.ActuatorInterface`); no wire format here.
- :mod:`~hexactl.control.core` — the controller: one cycle shaped read → update → write
  (feedback, FK, commands, supervision, motion, set-points) and the state machine, over
  its named parts: :mod:`~hexactl.control.pose_measurement` (FK of the feedback),
  :mod:`~hexactl.control.command_inbox` (commands per cycle, deadlines, verdicts),
  :mod:`~hexactl.control.supervisor` (heartbeats, actuator faults, set-points applied,
  link health, E-stop timing), :mod:`~hexactl.control.motion` (trajectory, leg lock,
  sequences through :mod:`~hexactl.control.sequence_player`, set-points through
  :mod:`~hexactl.control.setpoint_path` with :mod:`~hexactl.control.calibration_ramp`);
  :mod:`~hexactl.control.preconditions` (the ``check_*`` rules on a typed view) and
  :mod:`~hexactl.control.snapshot` (what a cycle publishes).
- :mod:`~hexactl.control.loop` — the manager: the real-time thread on absolute deadlines,
  with :mod:`~hexactl.control.realtime` (scheduling, memory, GIL, gc) and
  :mod:`~hexactl.control.stats` (lateness and compute percentiles).
- :mod:`~hexactl.control.controller` — the facade the API calls: validation and planning
  in the caller's thread (:mod:`~hexactl.control.planning`,
  :mod:`~hexactl.control.calibration_checks`), commands to the loop
  (:mod:`~hexactl.control.commands`) through its host (:mod:`~hexactl.control.host`: the
  loop's thread in this process, or a loop in another process) with
  :mod:`~hexactl.control.submitter`, results (:mod:`~hexactl.control.results`) and
  :mod:`~hexactl.control.telemetry`.
- Pure pieces: :mod:`~hexactl.control.trajectory` (ruckig in pose space),
  leg-lock projection from :mod:`hexactl.kinematics.leg_lock`,
  :mod:`~hexactl.control.guard` (stroke and velocity limit of every set-point),
  :mod:`~hexactl.control.sequences` (the validated model, built-ins, dwell records),
  :mod:`~hexactl.control.bounds` (a motion's numbers' bounds, which the CLI reads too).
"""
