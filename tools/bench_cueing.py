"""The motion cueing of the shipped manoeuvres on the nominal geometry, with and without
the workspace-aware gain, and the washout filter's cost per step; prints a markdown table.

Per manoeuvre and mode (default parameters, config/cueing.toml):

- RMS error: over the samples, |vehicle − platform| specific force (m/s², all three axes),
  the platform's being what its planned poses make felt (hexactl.cueing.washout);
- peak stroke use: the largest fraction, over the samples and legs, of the stroke margin
  from the zero posture's sensor reading to the stroke's end moved toward;
- peak workspace use: the largest fraction of the way to the first limit (any: stroke,
  cones, envelope, singularity) along the line from the zero posture;
- peak leg speed: the fastest sensor reading change between samples (mm/s), beside the
  geometry's ``leg_velocity_mm_s`` (reachability does not include it: the stream mode's
  tracking holds the legs to it, so a faster plan is followed with a lag);
- limited: the share of samples the limiter changed;
- plan: the wall-clock time of :func:`hexactl.application.cueing.plan_cue`;
- as performed: the RMS error of what the loop's commanded poses make felt, the plan
  streamed at its own rate (as ``hexactl cue`` does) into the 500 Hz loop on ideal
  actuators in simulated time (tools/simulated_stream.py: no host's timing in it), each
  commanded pose taken at the instant of the vehicle's sample it is compared with.

A row with the platform at rest gives the RMS error of no cueing at all, for reference.

The step cost is the median over ``--batches`` batches of 100 :meth:`WashoutFilter.step`
calls at a 2 ms period, fed the lane change's samples (``time.perf_counter_ns`` around each
batch, divided by 100).

    python3 tools/bench_cueing.py [--batches 200]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from itertools import cycle, islice
from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))
sys.path.insert(0, str(REPOSITORY / "tools"))

from hexactl.adapters.files.cueing_file import (  # noqa: E402
    load_cueing_parameters,
    load_vehicle_trajectory,
)
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.application.cueing import plan_cue  # noqa: E402
from hexactl.cueing.washout import (  # noqa: E402
    WashoutFilter,
    perceived_specific_force,
    rms_difference,
    wash_out,
)
from hexactl.cueing.workspace_gain import ray_reach, stroke_use  # noqa: E402
from hexactl.kinematics.workspace import assess_poses  # noqa: E402
from simulated_stream import perform  # noqa: E402

MANOEUVRES = ("braking", "lane_change")
STEPS_PER_BATCH = 100


def performed(plan, geometry) -> tuple[float, int]:
    """The RMS error (m/s²) of the specific force the loop's commanded poses make felt, the
    plan streamed into it at the plan's rate in simulated time, and the loop's guard clamps."""
    commanded, clamps = perform(plan.poses, plan.period_s, geometry)
    return rms_difference(plan.vehicle_specific_force, perceived_specific_force(commanded, plan.period_s)), clamps


def step_cost_us(parameters, vehicle, batches: int) -> float:
    washout = WashoutFilter(parameters, 0.002)
    samples = list(zip(vehicle.specific_force.tolist(), vehicle.angular_rate.tolist()))
    feed = cycle(samples)
    per_step = []
    for _ in range(batches):
        batch = list(islice(feed, STEPS_PER_BATCH))
        start = time.perf_counter_ns()
        for force, rate in batch:
            washout.step(force, rate)
        per_step.append((time.perf_counter_ns() - start) / STEPS_PER_BATCH / 1000.0)
    return statistics.median(per_step)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", type=int, default=200, help="batches of 100 steps timed (default 200)")
    arguments = parser.parse_args()
    geometry = load_geometry(REPOSITORY / "config" / "platform.toml")
    parameters = load_cueing_parameters(REPOSITORY / "config" / "cueing.toml")
    print(f"| manoeuvre | workspace-aware gain | RMS error, m/s² | peak stroke use | peak workspace use | "
          f"peak leg speed, mm/s (limit {geometry.limits.leg_velocity_mm_s:g}) | limited | plan, s | "
          f"RMS error as performed, m/s² (guard clamps) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in MANOEUVRES:
        vehicle = load_vehicle_trajectory(REPOSITORY / "config" / "vehicles" / f"{name}.csv")
        channels = wash_out(parameters, vehicle)
        at_rest = rms_difference(vehicle.specific_force, perceived_specific_force(np.zeros((len(vehicle), 6)), 1.0))
        print(f"| {name} | (no cueing: the platform at rest) | {at_rest:.3f} | 0 | 0 | 0 | | | |")
        for with_gain in (True, False):
            start = time.perf_counter()
            plan = plan_cue(vehicle, parameters, geometry, workspace_gain=with_gain)
            elapsed = time.perf_counter() - start
            poses = np.array(plan.poses)
            limited = np.any(poses != channels.poses(plan.gain), axis=1).mean()
            moving = np.any(poses != 0.0, axis=1)
            workspace = (1.0 / ray_reach(geometry, poses[moving])).max() if moving.any() else 0.0
            readings = np.array([assessment.sensor_mm for assessment in assess_poses(geometry, poses)])
            leg_speed = np.abs(np.diff(readings, axis=0)).max() / plan.period_s
            mode = f"on ({plan.gain:.2f})" if with_gain else "off (limiter only)"
            error, clamps = performed(plan, geometry)
            print(f"| {name} | {mode} | {plan.rms_error:.3f} | {stroke_use(geometry, poses).max():.2f} | "
                  f"{workspace:.2f} | {leg_speed:.0f} | {limited:.0%} | {elapsed:.2f} | {error:.3f} ({clamps}) |")
    cost = step_cost_us(parameters, load_vehicle_trajectory(REPOSITORY / "config" / "vehicles" / "lane_change.csv"),
                        arguments.batches)
    print(f"\nWashout filter step: median {cost:.1f} µs ({arguments.batches} batches of {STEPS_PER_BATCH} steps)")


if __name__ == "__main__":
    main()
