"""The motion cueing's parameters: the washout filter's channels and the use of the workspace.

One frozen model, :class:`CueingParameters`, with a table per part; its file form is
``config/cueing.toml`` (read by :mod:`hexactl.adapters.files.cueing_file`), where every
key is commented with its effect. Every value has a default, tuned for the nominal
1500/900 mm hexapod (``config/platform.toml``) and a car; docs/cueing.md has the table.

Axes: the vehicle's body axes x forward, y left, z up and the platform's x, y, z at the
zero posture are the same axes (the occupant faces +x). Break frequencies are in rad/s.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator
from hexactl.kinematics.numbers import Number

NonNegative = Annotated[Number, Field(ge=0)]
Positive = Annotated[Number, Field(gt=0)]


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class TranslationalChannel(_Frozen):
    """The onset cue: the vehicle's specific force less gravity, scaled, high-passed and
    integrated twice to the platform's position; per axis x, y, z.

    Acceleration to position is ``gain · s / ((s² + 2ζω·s + ω²)(s + ω_b))``: a third-order
    high-pass (a second-order one at ω, ζ times a first-order one at ω_b) and the double
    integration. With ``washout_rad_s`` 0 the high-pass is second-order and a sustained
    acceleration leaves the platform displaced by ``gain·a/ω²`` instead of returning it."""

    gain: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (0.5, 0.5, 0.5), description="x, y, z: scale of the specific force the channel reproduces, dimensionless (0: off)")
    break_rad_s: tuple[Positive, Positive, Positive] = Field(
        (1.0, 1.0, 2.0), description="x, y, z: the second-order high-pass's break frequency ω, rad/s")
    damping: tuple[Positive, Positive, Positive] = Field(
        (1.0, 1.0, 1.0), description="x, y, z: the second-order high-pass's damping ratio ζ, dimensionless")
    washout_rad_s: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (0.2, 0.2, 0.5), description="x, y, z: the first-order high-pass's break frequency ω_b, rad/s (0: none)")


class RotationalChannel(_Frozen):
    """The vehicle's angular rate, scaled, high-passed and integrated to the platform's
    roll, pitch and yaw: rate to angle is ``gain · s / (s² + 2ζω·s + ω²)``, so a sustained
    rate (a steady turn) tilts or turns the platform for a while and then returns it."""

    gain: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (0.5, 0.5, 0.5), description="roll, pitch, yaw: scale of the angular rate reproduced, dimensionless (0: off)")
    break_rad_s: tuple[Positive, Positive, Positive] = Field(
        (1.0, 1.0, 1.0), description="roll, pitch, yaw: the high-pass's break frequency ω, rad/s")
    damping: tuple[Positive, Positive, Positive] = Field(
        (1.0, 1.0, 1.0), description="roll, pitch, yaw: the high-pass's damping ratio ζ, dimensionless")


class TiltCoordination(_Frozen):
    """The sustained cue: the x and y specific force, scaled and low-passed, becomes a tilt
    of the platform whose gravity component the occupant feels as that force: a forward
    acceleration tilts the nose up (negative pitch), a leftward one rolls the left side up
    (positive roll). The tilt is at most ``limit_deg`` from level and turns at most
    ``rate_limit_deg_s``, below what the occupant's vestibular system notices."""

    gain: tuple[NonNegative, NonNegative] = Field(
        (1.0, 1.0), description="x (pitch), y (roll): scale of the sustained specific force reproduced (0: off)")
    break_rad_s: Positive = Field(3.0, description="the second-order low-pass's break frequency, rad/s")
    damping: Positive = Field(1.0, description="the second-order low-pass's damping ratio, dimensionless")
    rate_limit_deg_s: Positive = Field(
        3.0, description="the fastest the tilt turns (about any horizontal axis), deg/s")
    limit_deg: Number = Field(15.0, gt=0, lt=90, description="the largest tilt from level (in any direction), deg")


class WorkspaceUse(_Frozen):
    """How a cue is fitted into the platform's workspace (:mod:`hexactl.cueing.workspace_gain`).

    A pose's *use* of the workspace is the fraction of the way from the zero posture to
    the first limit along the straight line (in pose space) through it: below 1 reachable."""

    use_fraction: Number = Field(
        0.85, gt=0, le=1, description="the workspace-aware gain keeps every pose's use at most this, dimensionless")
    max_gain: Number = Field(
        2.5, gt=0, le=100, description="the largest workspace-aware gain on the onset (high-pass) channels, "
        "dimensionless, at most 100")
    limiter_knee: Number = Field(
        0.75, gt=0, lt=1, description="the limiter leaves poses of a use up to this alone, dimensionless")
    limiter_ceiling: Number = Field(
        0.97, gt=0, lt=1, description="no pose the limiter passes has a use above this, dimensionless")

    @model_validator(mode="after")
    def _knee_below_ceiling(self) -> WorkspaceUse:
        if not self.limiter_knee < self.limiter_ceiling:
            raise ValueError(f"limiter_knee {self.limiter_knee:g} must be below limiter_ceiling "
                             f"{self.limiter_ceiling:g}: the limiter bends poses between the two")
        if self.use_fraction > self.limiter_ceiling:  # found from outside: 0.99 over 0.97, y at 911 mm/s
            raise ValueError(f"use_fraction {self.use_fraction!r} must be at most limiter_ceiling "
                             f"{self.limiter_ceiling!r}: the gain would fit cues into a workspace the limiter then cuts")
        return self


class CueingParameters(_Frozen):
    """Everything the motion cueing is tuned by; ``config/cueing.toml`` is its file."""

    translational: TranslationalChannel = TranslationalChannel()
    rotational: RotationalChannel = RotationalChannel()
    tilt: TiltCoordination = TiltCoordination()
    workspace: WorkspaceUse = WorkspaceUse()
