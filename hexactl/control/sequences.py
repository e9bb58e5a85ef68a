"""Motion sequences: the file format, the built-in test motions and the dwell records.

File format (TOML; poses relative to the zero posture, mm and deg)::

    name = "my_sweep"                 # required
    description = "optional text"

    [[waypoint]]
    pose = [100.0, 0.0, 0.0, 0.0, 0.0, 0.0]   # [x, y, z, roll, pitch, yaw]
    duration = 4.0    # optional, s: the move takes at least this long (to one loop period); at most 600
    dwell = 2.0       # optional, s: stay this long on arrival (default 0); at most 86400

    [[waypoint]]
    pose = [0.0, 0.0, 0.0, 0.0, 5.0, 0.0]
    speed = 0.5       # optional, (0, 1]: fraction of the velocity limits; not with duration

A sequence is validated whole before anything moves (every move path, see
:mod:`hexactl.control.planning`). During playback the controller records, at the end of
each waypoint's dwell (the platform settled, the instrument done), the commanded and the
measured pose: :class:`DwellRecord`; :func:`dwell_rows` turns records into table rows
for a CSV writer (an adapter's job).
"""

from __future__ import annotations

import tomllib
from collections.abc import Sequence
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS
from hexactl.control.planning import MAX_DWELL_S, MAX_MOTION_S, Waypoint
from hexactl.kinematics.geometry import Pose6, describe_validation_error
from hexactl.kinematics.pose import POSE_AXES


class SequenceError(ValueError):
    """A sequence could not be read; the message names each problem."""


class SequenceWaypoint(BaseModel):
    """One ``[[waypoint]]`` table."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    pose: Pose6 = Field(description="relative to the zero posture, mm and deg")
    duration: float | None = Field(default=None, gt=0, le=MAX_MOTION_S, description="minimum move duration, s")
    speed: float | None = Field(default=None, gt=0, le=1, description="fraction of the velocity limits")
    dwell: float = Field(default=0.0, ge=0, le=MAX_DWELL_S, description="time to stay on arrival, s")

    @model_validator(mode="after")
    def _one_pace(self) -> SequenceWaypoint:
        if self.duration is not None and self.speed is not None:
            raise ValueError("give a duration or a speed, not both")
        return self


class MotionSequence(BaseModel):
    """A named list of waypoints (see the module's file format)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, populate_by_name=True)

    name: str = Field(min_length=1)
    description: str = ""
    waypoints: tuple[SequenceWaypoint, ...] = Field(alias="waypoint", min_length=1)

    def planning_waypoints(self) -> list[Waypoint]:
        return [Waypoint(w.pose, w.duration, w.speed, w.dwell) for w in self.waypoints]


def sequence_from_mapping(data: object, source: str = "sequence") -> MotionSequence:
    """Validate parsed content; :class:`SequenceError` lists every problem."""
    try:
        return MotionSequence.model_validate(data)
    except ValidationError as error:
        raise SequenceError(describe_validation_error(error, source)) from None


def sequence_from_toml(text: str, source: str = "sequence") -> MotionSequence:
    """Parse a sequence file's text; :class:`SequenceError` names the problems."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as error:  # RecursionError: arrays nested 1000 deep
        raise SequenceError(f"{source}: not valid TOML: {error}") from None
    return sequence_from_mapping(data, source)


BUILTIN_DWELL_S = 2.0
"""Dwell of the built-in sequences at each waypoint, s."""

_PAPER_MOTIONS = {motion.name: motion for motion in PAPER_TEST_MOTIONS}

BUILTIN_SEQUENCES: tuple[str, ...] = tuple(_PAPER_MOTIONS)
"""The paper's test motions (:mod:`hexactl.calibration.test_motions` defines them)."""


def builtin_sequence(name: str, dwell_s: float = BUILTIN_DWELL_S) -> MotionSequence:
    """One of :data:`BUILTIN_SEQUENCES`, dwelling ``dwell_s`` at each waypoint; KeyError
    for another name."""
    motion = _PAPER_MOTIONS[name]
    return MotionSequence(name=motion.name, description=motion.title,
                          waypoints=tuple(SequenceWaypoint(pose=pose, dwell=dwell_s) for pose in motion.waypoints))


@dataclass(frozen=True, slots=True)
class DwellRecord:
    """Where the platform was told to be and where it was, at the end of a dwell.

    ``t_s``: monotonic time, s. Poses relative to the zero posture, mm and deg;
    ``pose_measured`` None when the feedback's forward kinematics failed. Legs: sensor mm.
    """

    sequence: str
    waypoint: int
    t_s: float
    pose_command: tuple[float, ...]
    pose_measured: tuple[float, ...] | None
    leg_setpoints: tuple[float, ...]
    leg_feedback: tuple[float, ...]


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
