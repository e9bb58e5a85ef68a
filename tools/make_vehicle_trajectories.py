"""Writes the two vehicle trajectories hexactl ships for motion cueing:
config/vehicles/braking.csv and config/vehicles/lane_change.csv (format: docs/cueing.md).

Both are a car on a level road sampled at 100 Hz, body axes x forward, y left, z up, with
a rigid body (no suspension: the body neither pitches nor rolls on its springs), so the
specific force is (a_x, a_y, g) in body axes and the angular rate (0, 0, yaw rate).

- **braking** (12 s): a point mass at 25 m/s for 2 s, then braking with a jerk-limited
  deceleration: up to 7 m/s² at 15 m/s³, held, and released at 10 m/s³ timed so that the
  car stops just as the deceleration reaches zero (about 6.2 s); then standing still.
- **lane_change** (12 s): a linear single-track (bicycle) model at a constant 20 m/s
  (1500 kg, yaw inertia 2500 kg·m², axle distances 1.2 m front and 1.5 m rear from the
  centre of mass, cornering stiffnesses 80 and 90 kN/rad: an understeering car) steered
  through a double lane change: after 1.5 s straight, a lane change to the left (3 s),
  1 s in that lane, and back (3 s). Each lane change's road-wheel angle is the pulse
  sin(2πτ) − ½·sin(4πτ) over τ ∈ [0, 1], which starts and ends with zero angle and zero
  steering rate (so the lateral jerk is bounded) and turns the heading back; its
  amplitude is set so that the largest lateral acceleration is 3.5 m/s² (the car moves
  about 3.3 m to the left and back). The model is integrated by fixed-step fourth-order
  Runge–Kutta, ten steps per sample.

Deterministic: no randomness and fixed-step integration, so running it again rewrites the
same files (tests/cueing/test_vehicle_files.py checks the shipped ones).

    python3 tools/make_vehicle_trajectories.py [--out config/vehicles]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from math import pi, sin
from pathlib import Path

import numpy as np

PERIOD_S = 0.01
DURATION_S = 12.0
GRAVITY_M_S2 = 9.81  # hexactl.cueing.washout.GRAVITY_M_S2: at rest the file reads (0, 0, g)
HEADER = "t_s,f_x,f_y,f_z,omega_x,omega_y,omega_z"

# Braking (point mass)
BRAKING_SPEED_M_S = 25.0
BRAKING_START_S = 2.0
BRAKING_DECELERATION_M_S2 = 7.0
BRAKING_APPLY_JERK_M_S3 = 15.0
BRAKING_RELEASE_JERK_M_S3 = 10.0

# Lane change (single-track model)
LANE_SPEED_M_S = 20.0
MASS_KG = 1500.0
YAW_INERTIA_KG_M2 = 2500.0
FRONT_AXLE_M, REAR_AXLE_M = 1.2, 1.5
FRONT_STIFFNESS_N_RAD, REAR_STIFFNESS_N_RAD = 80_000.0, 90_000.0
LANE_CHANGES = ((1.5, 3.0, +1.0), (5.5, 3.0, -1.0))  # (start s, duration s, direction: +1 to the left)
PEAK_LATERAL_M_S2 = 3.5
SUBSTEPS = 10


def sample_times() -> np.ndarray:
    return np.arange(round(DURATION_S / PERIOD_S) + 1) * PERIOD_S


def braking_deceleration(t: float) -> float:
    """The braking manoeuvre's deceleration at ``t`` (m/s², positive when slowing)."""
    a, apply, release = BRAKING_DECELERATION_M_S2, BRAKING_APPLY_JERK_M_S3, BRAKING_RELEASE_JERK_M_S3
    apply_s, release_s = a / apply, a / release
    speed_lost_ramping = a * a / (2 * apply) + a * a / (2 * release)
    hold_s = (BRAKING_SPEED_M_S - speed_lost_ramping) / a
    since = t - BRAKING_START_S
    if since <= 0:
        return 0.0
    if since < apply_s:
        return apply * since
    if since < apply_s + hold_s:
        return a
    if since < apply_s + hold_s + release_s:
        return a - release * (since - apply_s - hold_s)
    return 0.0


def braking() -> np.ndarray:
    """Rows of t, f (m/s²), ω (rad/s) for the braking manoeuvre."""
    times = sample_times()
    rows = np.zeros((len(times), 7))
    rows[:, 0] = times
    rows[:, 1] = [-braking_deceleration(t) for t in times]
    rows[:, 3] = GRAVITY_M_S2
    return rows


def steering_shape(t: float) -> float:
    """The road-wheel angle's shape at ``t`` (unit amplitude, rad): the lane changes' pulses."""
    for start, duration, direction in LANE_CHANGES:
        tau = (t - start) / duration
        if 0.0 <= tau <= 1.0:
            return direction * (sin(2 * pi * tau) - 0.5 * sin(4 * pi * tau))
    return 0.0


def single_track(state: np.ndarray, steering_rad: float) -> np.ndarray:
    """d/dt of (lateral velocity m/s, yaw rate rad/s) of the linear single-track model."""
    lateral, yaw_rate = state
    slip_front = (lateral + FRONT_AXLE_M * yaw_rate) / LANE_SPEED_M_S - steering_rad
    slip_rear = (lateral - REAR_AXLE_M * yaw_rate) / LANE_SPEED_M_S
    force_front, force_rear = -FRONT_STIFFNESS_N_RAD * slip_front, -REAR_STIFFNESS_N_RAD * slip_rear
    return np.array([(force_front + force_rear) / MASS_KG - LANE_SPEED_M_S * yaw_rate,
                     (FRONT_AXLE_M * force_front - REAR_AXLE_M * force_rear) / YAW_INERTIA_KG_M2])


def simulate_lane_change(steering: Callable[[float], float]) -> np.ndarray:
    """Rows of t, f, ω for the road-wheel angle ``steering(t)`` (rad), from driving straight."""
    times = sample_times()
    rows = np.zeros((len(times), 7))
    state = np.zeros(2)
    h = PERIOD_S / SUBSTEPS
    for n, t in enumerate(times):
        derivative = single_track(state, steering(t))
        lateral, yaw_rate = state
        rows[n] = (t, -lateral * yaw_rate, derivative[0] + LANE_SPEED_M_S * yaw_rate, GRAVITY_M_S2, 0.0, 0.0, yaw_rate)
        for k in range(SUBSTEPS):  # to the next sample, RK4
            s = t + k * h
            k1 = single_track(state, steering(s))
            k2 = single_track(state + h / 2 * k1, steering(s + h / 2))
            k3 = single_track(state + h / 2 * k2, steering(s + h / 2))
            k4 = single_track(state + h * k3, steering(s + h))
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return rows


def lane_change() -> np.ndarray:
    """Rows of t, f, ω for the double lane change with the steering amplitude that makes
    its largest lateral acceleration :data:`PEAK_LATERAL_M_S2` (the model is linear in the
    steering angle, so a run at unit amplitude gives the scale)."""
    unit = simulate_lane_change(steering_shape)
    amplitude = PEAK_LATERAL_M_S2 / np.max(np.abs(unit[:, 2]))
    return simulate_lane_change(lambda t: amplitude * steering_shape(t))


def csv_text(rows: np.ndarray) -> str:
    lines = [HEADER] + [f"{row[0]:.2f}," + ",".join(_number(value) for value in row[1:]) for row in rows]
    return "\n".join(lines) + "\n"


def _number(value: float) -> str:
    text = f"{value:.6f}"
    return "0.000000" if text == "-0.000000" else text  # no signed zeros from rounding


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "config" / "vehicles",
                        help="directory to write braking.csv and lane_change.csv into (default: config/vehicles)")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    for name, rows in (("braking", braking()), ("lane_change", lane_change())):
        path = arguments.out / f"{name}.csv"
        path.write_text(csv_text(rows), encoding="utf-8")
        force, rate = rows[:, 1:4], rows[:, 4:7]
        print(f"{path}: {len(rows)} samples, {rows[-1, 0]:.1f} s; |f_x| ≤ {np.max(np.abs(force[:, 0])):.2f}, "
              f"|f_y| ≤ {np.max(np.abs(force[:, 1])):.2f} m/s², |yaw rate| ≤ {np.max(np.abs(rate[:, 2])):.3f} rad/s")


if __name__ == "__main__":
    main()
