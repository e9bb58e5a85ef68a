"""Instrument files: which instrument measured the feature points, where it stood, and its
native noise (TOML). Two forms::

    kind = "theodolites"                  # the paper's: two stations, two angles each
    stations = [[4000, -3000, 1500, 0, 0, 140], [4000, 3000, 1500, 0, 0, -140]]
    angle_sigma_arcsec = 2.0

    kind = "tracker"                      # a laser tracker: range and two angles
    stations = [[-3500, 500, 1000, 0, 0, 10]]
    angle_sigma_arcsec = 1.0
    range_sigma_mm = 0.015

A station is its pose in the fixed frame (x, y, z mm; roll, pitch, yaw deg): its local x
axis is horizontal angle 0, its xy plane the horizontal. See
:mod:`hexactl.calibration.observations`.
"""

from __future__ import annotations

import os
import tomllib
from math import dist, radians
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from hexactl.adapters.files.text import read_text
from hexactl.calibration.observations import MIN_BASELINE_MM, Instrument, LaserTracker, Station, Theodolites
from hexactl.kinematics.validation_messages import describe_validation_error
from hexactl.kinematics.numbers import Number, SixNumbers

class InstrumentFileError(ValueError):
    """An instrument file that cannot be used; the message names the file, key and problem."""


class _InstrumentDescription(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    kind: Literal["theodolites", "tracker"]
    stations: tuple[SixNumbers, ...] = Field(description="each station's pose in the fixed frame, mm and deg")
    angle_sigma_arcsec: Number = Field(gt=0, description="each angle's noise, 1σ, arc-seconds")
    range_sigma_mm: Number | None = Field(default=None, gt=0, description="the tracker's range noise, 1σ, mm")

    @model_validator(mode="after")
    def _complete(self) -> _InstrumentDescription:
        stations = 2 if self.kind == "theodolites" else 1
        if len(self.stations) != stations:
            raise ValueError(f"stations: {self.kind} need {stations} station pose(s), got {len(self.stations)}")
        if (self.kind == "tracker") != (self.range_sigma_mm is not None):
            raise ValueError("range_sigma_mm: a tracker needs it, theodolites have none")
        if self.kind == "theodolites" and (baseline := dist(self.stations[0][:3], self.stations[1][:3])) < MIN_BASELINE_MM:
            raise ValueError(f"stations: the two theodolites stand at the same place ({baseline:.3g} mm apart): from "
                             "one place a point's two rays meet only at the station and nothing can be triangulated; "
                             "give each station's own position (x, y, z mm)")
        return self

    def instrument(self) -> Instrument:
        stations = tuple(Station(pose) for pose in self.stations)
        angle = radians(self.angle_sigma_arcsec / 3600.0)
        if self.kind == "theodolites":
            return Theodolites((stations[0], stations[1]), angle)
        assert self.range_sigma_mm is not None
        return LaserTracker(stations[0], self.range_sigma_mm, angle)


def parse_instrument(text: str, source: str) -> Instrument:
    """The instrument TOML ``text`` describes. Raises :class:`InstrumentFileError`."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InstrumentFileError(f"{source}: not valid TOML: {error}") from None
    try:
        return _InstrumentDescription.model_validate(document).instrument()
    except ValidationError as error:
        raise InstrumentFileError(describe_validation_error(error, source, model=_InstrumentDescription)) from None


def load_instrument(path: str | os.PathLike[str]) -> Instrument:
    """Read and validate an instrument file. Raises :class:`InstrumentFileError`."""
    return parse_instrument(read_text(path, InstrumentFileError), str(path))
