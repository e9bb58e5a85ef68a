"""The wave generator's waves: a periodic motion on one or more axes of a frame.

A :class:`WaveSpec` is what the operator asks for; a :class:`WavePath` is the position it
commands at each loop cycle, oscillating about the start pose (at rest) and multiplied by
an envelope that ramps in and out with a quintic smoothstep, so that position, velocity
and acceleration are continuous from rest and back to it. The planner
(:mod:`~hexactl.control.wave_planning`) validates :meth:`WavePath.at` of every cycle, and
the loop's :class:`~hexactl.control.wave_player.WavePlayer` commands :meth:`WavePath.at`
of the same cycles: one function, the same times, so what was validated is what runs
(the reason :mod:`hexactl.control.trajectory` previews the generator it runs).

Coordinates: relative mm/rad for frame zero; the tool's pose in the work frame
(:class:`~hexactl.kinematics.axes.ToolInWorkMmRad`) for the work and the tool frame. In the
tool frame the displacement is composed on the tool's own axes at the start pose, so a
rotation turns about the pivot point. Pure: no I/O.
"""

from __future__ import annotations

from math import ceil, radians, sin, tau
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from hexactl.control.bounds import MAX_CYCLES, MAX_FREQUENCY_HZ, MAX_PHASE_DEG, amplitude_problem, ramp_problem
from hexactl.control.frames import Coordinates, Frame
from hexactl.kinematics.axes import POSE_AXES, AxisName
from hexactl.kinematics.frames import compose, pose_of, transform_of


class WaveAxis(BaseModel):
    """One axis's oscillation: ``amplitude`` mm (x, y, z) or deg (roll, pitch, yaw),
    ``phase_deg`` its phase at the start."""

    # strict: the API refuses "2" for a number, and an API request holds these
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, strict=True)

    amplitude: float = Field(description="peak displacement from the start pose: mm for x, y, z; deg for roll, "
                             "pitch, yaw")
    phase_deg: float = Field(default=0.0, ge=-MAX_PHASE_DEG, le=MAX_PHASE_DEG, description="phase at the start, deg")


class WaveSpec(BaseModel):
    """A wave: ``axes`` oscillate as ``amplitude·sin(2π·frequency_hz·t + phase)`` about the
    start pose in ``frame`` for ``cycles`` periods, the amplitude ramped in over the first
    ``ramp_cycles`` periods and out over the last as many.

    :raises pydantic.ValidationError: naming the field and the bound
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    # not strict: the API's strict requests give the frame as its name
    frame: Frame = Field(default=Frame.ZERO, strict=False, description="zero: the axes of the pose relative to the "
                         "zero posture; work: of the tool's pose in the work frame; tool: the tool's own axes at the "
                         "start pose "
                         "(rotations about the pivot point)")
    frequency_hz: float = Field(gt=0.0, le=MAX_FREQUENCY_HZ, description="periods per second")
    cycles: int = Field(ge=1, le=MAX_CYCLES, description="periods, the ramps included")
    ramp_cycles: float = Field(default=1.0, gt=0.0, description="periods the amplitude takes to ramp in, and again "
                               "to ramp out (a quintic smoothstep: from and to rest without a jump in acceleration); "
                               "at most half of cycles; default 1, or 0.5 for a wave of one period")
    axes: dict[AxisName, WaveAxis] = Field(min_length=1, description="the oscillating axes, by name")
    shape: Literal["sine"] = Field(default="sine", description="the waveform")

    @model_validator(mode="before")
    @classmethod
    def _one_period_ramps_over_its_halves(cls, data: Any) -> Any:
        # The default ramp (one period in, one out) does not fit a wave of one period, which
        # an operator asking for one means to run: it ramps in over its first half instead.
        if isinstance(data, dict) and "ramp_cycles" not in data and type(data.get("cycles")) is int \
                and data["cycles"] == 1:
            return {**data, "ramp_cycles": 0.5}
        return data

    @model_validator(mode="after")
    def _consistent(self) -> WaveSpec:
        if problem := ramp_problem(self.ramp_cycles, self.cycles):
            raise ValueError(f"ramp_cycles {problem}")
        for name, axis in self.axes.items():
            if problem := amplitude_problem(name, axis.amplitude):
                raise ValueError(problem)
        if not any(axis.amplitude for axis in self.axes.values()):
            raise ValueError("every amplitude is 0: the wave would move nothing")
        return self

    @property
    def duration_s(self) -> float:
        return self.cycles / self.frequency_hz


def envelope(u: float) -> float:
    """The quintic smoothstep at ``u`` in [0, 1]: 0 → 1 with zero first and second
    derivative at both ends."""
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


class WavePath:
    """The positions of ``spec`` from ``start`` (at rest, in the wave's coordinates: see
    the module docstring) for a loop running every ``period_s``. Immutable."""

    def __init__(self, spec: WaveSpec, start: Coordinates, period_s: float) -> None:
        self.spec = spec
        self.start = start
        self.period_s = period_s
        self.duration_s = spec.duration_s
        self.ramp_s = spec.ramp_cycles / spec.frequency_hz
        self.samples = ceil(self.duration_s / period_s - 1e-9)
        """Cycles the wave runs; :meth:`at` is ``start`` from this one on."""
        omega = tau * spec.frequency_hz
        self._terms = tuple(
            (POSE_AXES.index(name), axis.amplitude if name in ("x", "y", "z") else radians(axis.amplitude), omega,
             radians(axis.phase_deg))
            for name, axis in spec.axes.items())
        self._coordinates = type(start)
        self._on_tool = spec.frame is Frame.TOOL
        self._start_transform = transform_of(start)

    def envelope_at(self, t: float) -> float:
        """The amplitude's factor at ``t`` s from the start: 0 at both ends, 1 between the ramps."""
        if t <= 0.0 or t >= self.duration_s:
            return 0.0
        ramp = self.ramp_s
        if t < ramp:
            return envelope(t / ramp)
        if t > self.duration_s - ramp:
            return envelope((self.duration_s - t) / ramp)
        return 1.0

    def _displacement_at(self, t: float) -> list[float]:
        """The displacement from the start ``t`` s after it (mm, rad), per axis."""
        scale = self.envelope_at(t)
        offset = [0.0] * 6
        for index, amplitude, omega, phase in self._terms:
            offset[index] = scale * amplitude * sin(omega * t + phase)
        return offset

    def at(self, k: int) -> Coordinates:
        """The position commanded ``k`` cycles after the start (the start itself for
        k ≤ 0 and from :attr:`samples` on)."""
        return self.at_time(k * self.period_s)

    def at_time(self, t: float) -> Coordinates:
        """The position on the same path at ``t`` s from the start (between cycles: a
        stopped wave brakes along its path, :class:`~hexactl.control.wave_player.WavePlayer`);
        the start itself for t ≤ 0 and from :attr:`samples` cycles on."""
        if t <= 0.0 or t >= self.samples * self.period_s:
            return self.start
        return self._position(self._displacement_at(t))

    def _position(self, offset: list[float]) -> Coordinates:
        start = self.start
        if not self._on_tool:
            return tuple.__new__(self._coordinates, [s + d for s, d in zip(start, offset)])
        moved = pose_of(compose(self._start_transform, transform_of(offset)))
        # pose_of gives angles in (-π, π]: keep them continuous with the start's
        angles = [a + tau * round((s - a) / tau) for a, s in zip(moved[3:], start[3:])]
        return tuple.__new__(self._coordinates, (*moved[:3], *angles))

    def cycle_at(self, k: int) -> int:
        """The wave's period (1-based, at most ``cycles``) that cycle ``k`` is in."""
        return min(self.spec.cycles, 1 + int(k * self.period_s * self.spec.frequency_hz))

