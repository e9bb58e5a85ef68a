"""Plots the motion cueing of the shipped manoeuvres on the nominal geometry, into
docs/images/cueing-braking.png and docs/images/cueing-lane-change.png (docs/cueing.md).

Each figure: the vehicle's specific force along the manoeuvre's axis against the one the
platform's motion makes felt, with and without the workspace-aware gain; then the
platform's translation and rotation channels, with (solid) and without (dashed) it.
Default parameters (config/cueing.toml), geometry config/platform.toml.

    python3 tools/plot_cueing.py [--out docs/images]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))

from hexactl.adapters.files.cueing_file import (  # noqa: E402
    load_cueing_parameters,
    load_vehicle_trajectory,
)
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.application.cueing import CuePlan, plan_cue  # noqa: E402
from hexactl.kinematics.axes import POSE_AXES  # noqa: E402

MANOEUVRES = (  # file, figure, title, axis of the specific force (0 x, 1 y), its name
    ("braking", "cueing-braking.png", "Braking from 25 m/s at 7 m/s²", 0, "longitudinal f_x"),
    ("lane_change", "cueing-lane-change.png", "Double lane change at 20 m/s, 3.5 m/s²", 1, "lateral f_y"),
)
NEGLIGIBLE = (1.0, 1.0, 1.0, 0.05, 0.05, 0.05)  # mm, deg: a channel that never moves more is not drawn


def figure(title: str, axis: int, force_name: str, with_gain: CuePlan, without: CuePlan) -> plt.Figure:
    times = np.arange(len(with_gain.poses)) * with_gain.period_s
    fig, (force, translation, rotation) = plt.subplots(3, 1, figsize=(9, 9), sharex=True,
                                                        gridspec_kw={"height_ratios": [1.4, 1, 1]})
    force.plot(times, with_gain.vehicle_specific_force[:, axis], color="black", label="vehicle")
    force.plot(times, with_gain.platform_specific_force[:, axis], color="tab:blue",
               label=f"platform, workspace-aware gain {with_gain.gain:.2f} (RMS error {with_gain.rms_error:.2f} m/s²)")
    force.plot(times, without.platform_specific_force[:, axis], color="tab:orange", linestyle="--",
               label=f"platform, no gain: limiter only (RMS error {without.rms_error:.2f} m/s²)")
    force.set_ylabel(f"{force_name}, m/s²")
    force.set_title(f"{title}: specific force felt (RMS error over all three axes)")
    force.legend(loc="best", fontsize="small")
    for panel, axes, unit in ((translation, range(3), "mm"), (rotation, range(3, 6), "deg")):
        poses_with, poses_without = np.array(with_gain.poses), np.array(without.poses)
        for index, colour in zip(axes, ("tab:red", "tab:green", "tab:purple")):
            if max(np.abs(poses_with[:, index]).max(), np.abs(poses_without[:, index]).max()) < NEGLIGIBLE[index]:
                continue
            panel.plot(times, poses_with[:, index], color=colour, label=f"{POSE_AXES[index]}, gain")
            panel.plot(times, poses_without[:, index], color=colour, linestyle="--", label=f"{POSE_AXES[index]}, no gain")
        panel.set_ylabel(f"platform pose, {unit}")
        panel.legend(loc="best", fontsize="small", ncol=2)
    rotation.set_xlabel("time, s")
    for panel in (force, translation, rotation):
        panel.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=REPOSITORY / "docs" / "images", help="directory for the PNGs")
    arguments = parser.parse_args()
    geometry = load_geometry(REPOSITORY / "config" / "platform.toml")
    parameters = load_cueing_parameters(REPOSITORY / "config" / "cueing.toml")
    arguments.out.mkdir(parents=True, exist_ok=True)
    for name, image, title, axis, force_name in MANOEUVRES:
        vehicle = load_vehicle_trajectory(REPOSITORY / "config" / "vehicles" / f"{name}.csv")
        plans = [plan_cue(vehicle, parameters, geometry, workspace_gain=gain) for gain in (True, False)]
        fig = figure(title, axis, force_name, *plans)
        fig.savefig(arguments.out / image, dpi=100)
        plt.close(fig)
        print(arguments.out / image)


if __name__ == "__main__":
    main()
