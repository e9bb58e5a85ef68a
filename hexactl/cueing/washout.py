"""The classical washout filter (Reid–Nahon style): a vehicle's specific force and angular
rate to platform poses, and the specific force a platform's motion makes its occupant feel.

Inputs are the vehicle's, in its body axes x forward, y left, z up: the specific force
``f`` (m/s², what an accelerometer in the vehicle reads: (0, 0, +g) at rest, ``f_x < 0``
braking) and the angular rate ``ω`` (rad/s, right-handed: ``ω_x > 0`` rolls the left side
up, ``ω_y > 0`` pitches the nose down, ``ω_z > 0`` turns left). The platform's axes at the
zero posture are the same, and its pose follows hexactl's convention (T = Rz(yaw)·Ry(pitch)·
Rx(roll), :mod:`hexactl.kinematics.rotation`): positive pitch tips +x (the nose) down.

Three channels, summed into a pose relative to the zero posture (mm, deg):

- translational: ``f − (0, 0, g)``, scaled, third-order high-pass, integrated twice →
  x, y, z (the onset of an acceleration, then back to the zero posture);
- rotational: ``ω``, scaled, second-order high-pass, integrated → roll, pitch, yaw (taken
  as Euler rates: the channel's angles stay small, a few degrees);
- tilt coordination: ``f_x, f_y``, scaled, second-order low-pass → the tilt whose gravity
  component is that force (nose up for a forward force: pitch = −asin(f_x/g); left side
  up for a leftward one: roll = asin(f_y/(g·cos pitch))), within a tilt limit and a tilt
  rate limit.

The linear channels are the continuous filters of :mod:`hexactl.cueing.parameters`
discretised by the bilinear transform at the sample period, as cascades of second-order
sections. :class:`WashoutFilter` steps one sample at a time (a stream);
:func:`wash_out` runs it over a whole :class:`VehicleTrajectory`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from math import asin, atan2, degrees, hypot, radians, sqrt

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from hexactl.cueing.parameters import CueingParameters
from hexactl.kinematics.axes import RelativeMmDeg
from hexactl.kinematics.rotation import rotation_matrices

GRAVITY_M_S2 = 9.81
"""g: the specific force of a vehicle at rest is (0, 0, +g); gravity is (0, 0, −g)."""

_MM_PER_M = 1000.0


@dataclass(frozen=True)
class VehicleTrajectory:
    """A vehicle's motion sampled every ``period_s`` (s): ``specific_force`` (N, 3) m/s² and
    ``angular_rate`` (N, 3) rad/s, body axes x forward, y left, z up. :class:`ValueError`
    if the shapes disagree, there are no samples, or a value is not finite."""

    period_s: float
    specific_force: NDArray[np.float64]
    angular_rate: NDArray[np.float64]

    def __post_init__(self) -> None:
        force = np.asarray(self.specific_force, dtype=float)
        rate = np.asarray(self.angular_rate, dtype=float)
        if force.ndim != 2 or force.shape[1] != 3 or force.shape != rate.shape or len(force) == 0:
            raise ValueError(f"specific force {force.shape} and angular rate {rate.shape} must both be (N, 3), N ≥ 1")
        if not (np.all(np.isfinite(force)) and np.all(np.isfinite(rate))):
            raise ValueError("specific force and angular rate must be finite numbers")
        if not (np.isfinite(self.period_s) and self.period_s > 0):
            raise ValueError(f"the sample period must be a positive number of seconds, got {self.period_s}")
        object.__setattr__(self, "specific_force", force)
        object.__setattr__(self, "angular_rate", rate)

    def __len__(self) -> int:
        return len(self.specific_force)

    @property
    def times_s(self) -> NDArray[np.float64]:
        """Each sample's time from the first, s."""
        return np.arange(len(self)) * self.period_s


class _Sections:
    """A cascade of second-order sections (direct form II transposed) stepped with plain
    floats: at three sections numpy's per-call overhead would cost more than the arithmetic."""

    __slots__ = ("_coefficients", "_states")

    def __init__(self, zeros: Sequence[float], poles: Sequence[complex], gain: float, period_s: float) -> None:
        """The continuous filter ``gain·Π(s − zeros)/Π(s − poles)`` (s in rad/s), bilinear at ``period_s``."""
        discrete = signal.bilinear_zpk(np.asarray(zeros, dtype=float), np.asarray(poles), gain, 1.0 / period_s)
        sections = signal.zpk2sos(*discrete)
        self._coefficients = [(float(b0), float(b1), float(b2), float(a1), float(a2))
                              for b0, b1, b2, _, a1, a2 in sections]  # zpk2sos makes a0 = 1
        self._states = [[0.0, 0.0] for _ in self._coefficients]

    def step(self, value: float) -> float:
        for (b0, b1, b2, a1, a2), state in zip(self._coefficients, self._states):
            out = b0 * value + state[0]
            state[0] = b1 * value - a1 * out + state[1]
            state[1] = b2 * value - a2 * out
            value = out
        return value

    def reset(self) -> None:
        for state in self._states:
            state[0] = state[1] = 0.0


def _second_order_poles(break_rad_s: float, damping: float) -> list[complex]:
    """Roots of s² + 2ζω·s + ω²."""
    return list(np.roots([1.0, 2.0 * damping * break_rad_s, break_rad_s**2]))


def _translational_filter(gain: float, break_rad_s: float, damping: float, washout_rad_s: float,
                          period_s: float) -> _Sections:
    """Acceleration (m/s²) to position (m): gain·s/((s² + 2ζω·s + ω²)(s + ω_b)), or with
    ω_b = 0 gain/(s² + 2ζω·s + ω²) (the zero at 0 cancels the pole there)."""
    poles = _second_order_poles(break_rad_s, damping)
    if washout_rad_s > 0:
        return _Sections([0.0], [*poles, -washout_rad_s], gain, period_s)
    return _Sections([], poles, gain, period_s)


def _rotational_filter(gain: float, break_rad_s: float, damping: float, period_s: float) -> _Sections:
    """Angular rate (rad/s) to angle (rad): gain·s/(s² + 2ζω·s + ω²)."""
    return _Sections([0.0], _second_order_poles(break_rad_s, damping), gain, period_s)


def _tilt_low_pass(gain: float, break_rad_s: float, damping: float, period_s: float) -> _Sections:
    """Specific force to the specific force to tilt for (m/s²): gain·ω²/(s² + 2ζω·s + ω²)."""
    return _Sections([], _second_order_poles(break_rad_s, damping), gain * break_rad_s**2, period_s)


class _TiltCoordination:
    """The low-passed x and y specific force to the platform's (roll, pitch) in rad,
    within the tilt limit and rate limit (both on the tilt's magnitude, whatever its
    direction)."""

    __slots__ = ("_low_pass_x", "_low_pass_y", "_limit_rad", "_step_rad", "roll", "pitch")

    def __init__(self, parameters: CueingParameters, period_s: float) -> None:
        tilt = parameters.tilt
        self._low_pass_x = _tilt_low_pass(tilt.gain[0], tilt.break_rad_s, tilt.damping, period_s)
        self._low_pass_y = _tilt_low_pass(tilt.gain[1], tilt.break_rad_s, tilt.damping, period_s)
        self._limit_rad = radians(tilt.limit_deg)
        self._step_rad = radians(tilt.rate_limit_deg_s) * period_s
        self.roll = self.pitch = 0.0

    def step(self, force_x: float, force_y: float) -> None:
        across_x = self._low_pass_x.step(force_x) / GRAVITY_M_S2
        across_y = self._low_pass_y.step(force_y) / GRAVITY_M_S2
        across = across_x * across_x + across_y * across_y
        if across > 1.0:  # more than g sideways: the most a tilt gives is lying on the side
            norm = sqrt(across)
            across_x, across_y, along_z = across_x / norm, across_y / norm, 0.0
        else:
            along_z = sqrt(1.0 - across)
        # The tilt whose Tᵀ·(0, 0, g) is g·(across_x, across_y, along_z) (module docstring).
        pitch = -asin(across_x)
        roll = atan2(across_y, along_z)
        size = hypot(roll, pitch)
        if size > self._limit_rad:
            roll, pitch = roll * self._limit_rad / size, pitch * self._limit_rad / size
        turn_roll, turn_pitch = roll - self.roll, pitch - self.pitch
        turn = hypot(turn_roll, turn_pitch)
        if turn > self._step_rad:
            turn_roll, turn_pitch = turn_roll * self._step_rad / turn, turn_pitch * self._step_rad / turn
        self.roll += turn_roll
        self.pitch += turn_pitch

    def reset(self) -> None:
        self._low_pass_x.reset()
        self._low_pass_y.reset()
        self.roll = self.pitch = 0.0


class WashoutFilter:
    """The washout filter as a stream: one :meth:`step` per sample, every ``period_s`` (s).

    Starts, and :meth:`reset` returns it, at rest: the state of a vehicle standing or
    driving straight at a constant speed for long (f = (0, 0, g), ω = 0), with the
    platform at the zero posture."""

    def __init__(self, parameters: CueingParameters, period_s: float) -> None:
        if not period_s > 0:
            raise ValueError(f"the sample period must be a positive number of seconds, got {period_s}")
        translational, rotational = parameters.translational, parameters.rotational
        self.period_s = period_s
        self._translational = [
            _translational_filter(translational.gain[axis], translational.break_rad_s[axis],
                                 translational.damping[axis], translational.washout_rad_s[axis], period_s)
            for axis in range(3)]
        self._rotational = [
            _rotational_filter(rotational.gain[axis], rotational.break_rad_s[axis], rotational.damping[axis], period_s)
            for axis in range(3)]
        self._tilt = _TiltCoordination(parameters, period_s)

    def step(self, specific_force: Sequence[float], angular_rate: Sequence[float]) -> RelativeMmDeg:
        """The platform's pose (relative to the zero posture, mm and deg) for the next
        sample of the vehicle's specific force (m/s²) and angular rate (rad/s)."""
        x, y, z, roll, pitch, yaw, tilt_roll, tilt_pitch = self._advance(specific_force, angular_rate)
        return tuple.__new__(RelativeMmDeg, (x, y, z, roll + tilt_roll, pitch + tilt_pitch, yaw))

    def step_channels(self, specific_force: Sequence[float],
                      angular_rate: Sequence[float]) -> tuple[RelativeMmDeg, RelativeMmDeg]:
        """As :meth:`step`, the pose's two parts apart: the onset (translational and
        rotational channels) and the tilt coordination (roll and pitch only)."""
        x, y, z, roll, pitch, yaw, tilt_roll, tilt_pitch = self._advance(specific_force, angular_rate)
        return (tuple.__new__(RelativeMmDeg, (x, y, z, roll, pitch, yaw)),
                tuple.__new__(RelativeMmDeg, (0.0, 0.0, 0.0, tilt_roll, tilt_pitch, 0.0)))

    def reset(self) -> None:
        for channel in (*self._translational, *self._rotational):
            channel.reset()
        self._tilt.reset()

    def _advance(self, specific_force: Sequence[float], angular_rate: Sequence[float]) -> tuple[float, ...]:
        """x, y, z (mm), roll, pitch, yaw of the rotational channel and roll, pitch of the tilt (deg)."""
        force_x, force_y, force_z = specific_force
        rate_x, rate_y, rate_z = angular_rate
        translational, rotational = self._translational, self._rotational
        self._tilt.step(force_x, force_y)
        return (translational[0].step(force_x) * _MM_PER_M,
                translational[1].step(force_y) * _MM_PER_M,
                translational[2].step(force_z - GRAVITY_M_S2) * _MM_PER_M,
                degrees(rotational[0].step(rate_x)),
                degrees(rotational[1].step(rate_y)),
                degrees(rotational[2].step(rate_z)),
                degrees(self._tilt.roll),
                degrees(self._tilt.pitch))


@dataclass(frozen=True)
class WashoutChannels:
    """A whole trajectory's washout, its two parts apart, each (N, 6) relative mm/deg:
    ``onset`` (translational and rotational channels) and ``tilt`` (roll and pitch)."""

    onset: NDArray[np.float64]
    tilt: NDArray[np.float64]

    def poses(self, onset_gain: float = 1.0) -> NDArray[np.float64]:
        """(N, 6) poses relative to the zero posture (mm, deg): the tilt plus the onset
        scaled by ``onset_gain``."""
        return self.tilt + onset_gain * self.onset


def wash_out(parameters: CueingParameters, vehicle: VehicleTrajectory) -> WashoutChannels:
    """:class:`WashoutFilter` over a whole trajectory, from rest."""
    washout = WashoutFilter(parameters, vehicle.period_s)
    steps = [washout.step_channels(force, rate)
             for force, rate in zip(vehicle.specific_force.tolist(), vehicle.angular_rate.tolist())]
    return WashoutChannels(onset=np.array([onset for onset, _ in steps]), tilt=np.array([tilt for _, tilt in steps]))


def perceived_specific_force(poses_mm_deg: NDArray, period_s: float) -> NDArray[np.float64]:
    """The specific force (m/s², platform axes) an occupant of the platform feels at the
    moving frame's origin along (N, 6) poses relative to a level zero posture (mm, deg),
    sampled every ``period_s``: f = Tᵀ·(a − g), a the origin's acceleration (second
    differences of the position; the first and last samples repeat their neighbours'),
    g = (0, 0, −g). At rest and level it is (0, 0, +g), like the vehicle's."""
    poses = np.asarray(poses_mm_deg, dtype=float).reshape(-1, 6)
    position_m = poses[:, :3] / _MM_PER_M
    acceleration = np.zeros_like(position_m)
    if len(poses) >= 3:
        acceleration[1:-1] = (position_m[2:] - 2.0 * position_m[1:-1] + position_m[:-2]) / period_s**2
        acceleration[0], acceleration[-1] = acceleration[1], acceleration[-2]
    angles = np.radians(poses[:, 3:])
    rotations = rotation_matrices(angles[:, 0], angles[:, 1], angles[:, 2])
    felt = acceleration + np.array([0.0, 0.0, GRAVITY_M_S2])  # a − g
    return np.einsum("nji,nj->ni", rotations, felt)  # Tᵀ·(a − g)


def rms_difference(vehicle_force: NDArray, platform_force: NDArray) -> float:
    """RMS over the samples of |vehicle − platform| specific force (each (N, 3), m/s²)."""
    difference = np.asarray(vehicle_force, dtype=float) - np.asarray(platform_force, dtype=float)
    return float(np.sqrt(np.mean(np.sum(difference**2, axis=1))))
