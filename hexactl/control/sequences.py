"""Motion sequences: the validated model, the built-in test motions and the dwell records.

A sequence is a name and waypoints (poses relative to the zero posture, mm and deg, or
with ``frame = "work"`` the tool's poses in the operator's work frame; each with an
optional duration or speed, and a dwell). Its file format (TOML) and the dwell
records' table are :mod:`hexactl.adapters.files.sequence_file`'s. A sequence is validated
whole before anything moves (every move path, see :mod:`hexactl.control.planning`); it
holds at most :data:`~hexactl.control.planning.MAX_WAYPOINTS` waypoints.
During playback the controller records, at the end of each waypoint's dwell (the platform
settled, the instrument done), the commanded and the measured pose: :class:`DwellRecord`.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from hexactl.calibration.test_motions import PAPER_TEST_MOTIONS
from hexactl.kinematics.one_line import is_one_line
from hexactl.control.planning import MAX_DWELL_S, MAX_MOTION_S, MAX_WAYPOINTS, Waypoint, pace_problem, waypoint_count_problem
from hexactl.kinematics.axes import RelativeMmDeg, ToolInWorkMmDeg
from hexactl.kinematics.validation_messages import describe_validation_error
from hexactl.kinematics.numbers import Number


class SequenceError(ValueError):
    """A sequence could not be read; the message names each problem."""


class UnknownSequence(SequenceError, KeyError):
    """A name that is not one of :data:`BUILTIN_SEQUENCES`; the message lists them and
    names the closest, if one is close."""

    def __str__(self) -> str:  # KeyError's would quote the message
        return str(self.args[0])


def _one_line(name: str) -> str:
    if not is_one_line(name):
        raise ValueError(f"{name[:60]!r}: a sequence's name is one line of printable text (no line end, tab or other "
                         "control character)")
    return name


SequenceName = Annotated[str, Field(min_length=1, max_length=200, description="the sequence's name, for people: "
                                   "events, telemetry and recordings carry it; one line of printable text"),
                         AfterValidator(_one_line)]

Duration = Annotated[Number, Field(gt=0, le=MAX_MOTION_S, description="the move takes at least this long, s")]
Speed = Annotated[Number, Field(gt=0, le=1, description="fraction of the velocity limits, (0, 1]")]
Dwell = Annotated[Number, Field(ge=0, le=MAX_DWELL_S, description="time to stay on arrival, s")]


class Paced(BaseModel):
    """A move's pace: at least ``duration`` s, or ``speed`` of the velocity limits (sequence
    files, and the API's moves and inline sequences)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    duration: Duration | None = None
    speed: Speed | None = None

    @model_validator(mode="after")
    def _one_pace(self) -> Paced:
        if problem := pace_problem(self.duration, self.speed):
            raise ValueError(problem)
        return self


class SequenceWaypoint(Paced):
    """One ``[[waypoint]]`` table."""

    pose: RelativeMmDeg = Field(description="mm and deg: relative to the zero posture, or the tool's pose in the work "
                                "frame when the sequence's frame is work")
    dwell: Dwell = 0.0


class MotionSequence(BaseModel):
    """A named list of waypoints (see the module's file format)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, populate_by_name=True)

    name: SequenceName
    description: str = ""
    frame: Literal["zero", "work"] = Field(default="zero", description="what the poses are: relative to the zero "
                                           "posture (zero), or the tool's poses in the work frame (work)")
    waypoints: tuple[SequenceWaypoint, ...] = Field(alias="waypoint", description=(
        f"at least one, at most {MAX_WAYPOINTS} (hexactl.control.planning.MAX_WAYPOINTS: planning time grows with "
        "each)"), json_schema_extra={"minItems": 1})

    @field_validator("waypoints", mode="before")
    @classmethod
    def _counted(cls, value: object) -> object:
        """Counted before any waypoint is validated, let alone planned; here rather than by
        ``min_length``, which also reports a list whose waypoints all failed as empty."""
        if isinstance(value, dict):  # TOML's [waypoint] where [[waypoint]] was meant
            raise ValueError("write each waypoint as [[waypoint]] (double brackets: one table of a list), not "
                             "[waypoint]")
        if isinstance(value, (list, tuple)):
            if not value:
                raise ValueError("a sequence needs at least one [[waypoint]]")
            if problem := waypoint_count_problem(len(value)):
                raise ValueError(problem)
        return value

    def planning_waypoints(self) -> list[Waypoint]:
        in_work = self.frame == "work"
        return [Waypoint(ToolInWorkMmDeg._make(w.pose) if in_work else w.pose, w.duration, w.speed, w.dwell)
                for w in self.waypoints]


def sequence_from_mapping(data: object, source: str = "sequence") -> MotionSequence:
    """Validate parsed content; :class:`SequenceError` lists every problem."""
    try:
        return MotionSequence.model_validate(data)
    except ValidationError as error:
        raise SequenceError(describe_validation_error(error, source, model=MotionSequence)) from None


BUILTIN_DWELL_S = 2.0
"""Dwell of the built-in sequences at each waypoint, s."""

_PAPER_MOTIONS = {motion.name: motion for motion in PAPER_TEST_MOTIONS}

BUILTIN_SEQUENCES: tuple[str, ...] = tuple(_PAPER_MOTIONS)
"""The paper's test motions (:mod:`hexactl.calibration.test_motions` defines them)."""


def builtin_sequence(name: str, dwell_s: float = BUILTIN_DWELL_S) -> MotionSequence:
    """One of :data:`BUILTIN_SEQUENCES`, dwelling ``dwell_s`` at each waypoint.

    :raises UnknownSequence: for another name
    """
    motion = _PAPER_MOTIONS.get(name)
    if motion is None:
        near = difflib.get_close_matches(name.lower(), BUILTIN_SEQUENCES, n=1)  # X_SWEEP too
        guess = f"did you mean {near[0]!r}? " if near else ""
        raise UnknownSequence(f"{name!r} is not a built-in sequence ({guess}built in: {', '.join(BUILTIN_SEQUENCES)})")
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
