"""Motion sequence files and the dwell records' table.

File format (TOML; poses relative to the zero posture, mm and deg)::

    name = "my_sweep"                 # required
    description = "optional text"
    frame = "zero"                    # optional: "work" makes the poses the tool's in the work frame

    [[waypoint]]
    pose = [100.0, 0.0, 0.0, 0.0, 0.0, 0.0]   # [x, y, z, roll, pitch, yaw]
    duration = 4.0    # optional, s: the move takes at least this long (to one loop period); at most 600
    dwell = 2.0       # optional, s: stay this long on arrival (default 0); at most 86400

    [[waypoint]]
    pose = [0.0, 0.0, 0.0, 0.0, 5.0, 0.0]
    speed = 0.5       # optional, (0, 1]: fraction of the velocity limits; not with duration

The model it validates into is :class:`~hexactl.control.sequences.MotionSequence`. A file
(and a plan) holds at most :data:`~hexactl.control.planning.MAX_WAYPOINTS` (500) waypoints,
counted before any is planned: split a longer one into several.

A posture plan (the CSV ``hexactl plan-leglock`` writes, read by
:func:`~hexactl.adapters.files.measurements.parse_plan`) is a sequence too
(:func:`sequence_from_plan`): its rows' poses in order, each a waypoint at the default
pace (the velocity limits) dwelling :data:`~hexactl.control.sequences.BUILTIN_DWELL_S`;
the plan's ``leg`` and set-point columns are not acted on (playing locks nothing; with
the plan's leg locked at its planned length, each posture lies on the lock). Measuring
the postures is ``hexactl campaign``'s work.

:func:`dwell_header` and :func:`dwell_rows` lay out
:class:`~hexactl.control.sequences.DwellRecord` as the rows of a CSV file.
"""

from __future__ import annotations

import tomllib
from collections.abc import Sequence
from pathlib import PurePath

from pydantic import ValidationError

from hexactl.adapters.files.measurements import MeasurementFileError, parse_plan
from hexactl.control.planning import waypoint_count_problem
from hexactl.control.sequences import (
    BUILTIN_DWELL_S,
    DwellRecord,
    MotionSequence,
    SequenceError,
    SequenceWaypoint,
    sequence_from_mapping,
)
from hexactl.kinematics.axes import POSE_AXES
from hexactl.kinematics.validation_messages import describe_validation_error


def sequence_from_toml(text: str, source: str = "sequence") -> MotionSequence:
    """Parse a sequence file's text; :class:`SequenceError` names the problems."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as error:  # RecursionError: arrays nested 1000 deep
        raise SequenceError(f"{source}: not valid TOML: {error}") from None
    return sequence_from_mapping(data, source)


def sequence_from_plan(text: str, source: str) -> MotionSequence:
    """A posture plan's text as a sequence named after the file ``source`` (see the
    module's docstring). :class:`SequenceError` if it is not a plan, has no postures, or
    has bad rows (each named by its line): a plan plays whole or not at all."""
    try:
        plan = parse_plan(text, source)
    except MeasurementFileError as error:
        raise SequenceError(str(error)) from None
    if plan.problems:
        raise SequenceError("\n".join(f"{source}: {problem}" for problem in plan.problems))
    if not plan.poses:
        raise SequenceError(f"{source}: a header but no postures: a plan to play needs at least one row")
    if problem := waypoint_count_problem(len(plan.poses)):
        raise SequenceError(f"{source}: {problem}")
    waypoints, problems = [], []
    for pose, line in zip(plan.poses, plan.lines):
        try:
            waypoints.append(SequenceWaypoint(pose=pose, dwell=BUILTIN_DWELL_S))
        except ValidationError as error:  # a pose beyond any platform's reach
            problems.append(describe_validation_error(error, f"{source}: line {line}"))
    if problems:
        raise SequenceError("\n".join(problems))
    legs = sorted(set(plan.legs) - {0})
    locked = f", planned with leg {', '.join(map(str, legs))} locked" if legs else ""
    return MotionSequence(name=PurePath(source).stem or source,
                          description=f"{len(plan.poses)} postures of the plan {source}{locked}",
                          waypoints=tuple(waypoints))


def dwell_header() -> list[str]:
    """Column names of :func:`dwell_rows`."""
    return (["sequence", "waypoint", "t_s"]
            + [f"command_{a}" for a in POSE_AXES] + [f"measured_{a}" for a in POSE_AXES]
            + [f"setpoint_{i}" for i in range(1, 7)] + [f"feedback_{i}" for i in range(1, 7)])


def dwell_rows(records: Sequence[DwellRecord]) -> list[list[object]]:
    """One row per record in :func:`dwell_header`'s order; a missing measurement is
    six empty cells."""
    return [
        [r.sequence, r.waypoint, r.t_s, *r.pose_command,
         *(r.pose_measured if r.pose_measured is not None else [""] * 6),
         *r.leg_setpoints, *r.leg_feedback]
        for r in records
    ]
