"""Draw docs/frames.png: the work and tool frames and a rotation about the pivot point,
computed with hexactl's own kinematics on the nominal geometry (a side view, x–z plane).

    python3 tools/frames_figure.py [--out docs/frames.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.control.frames import OperatorFrames  # noqa: E402
from hexactl.kinematics.axes import ToolInWorkMmDeg  # noqa: E402
from hexactl.kinematics.frames import apply, transform_of  # noqa: E402

FRAMES = OperatorFrames(work=(0, 0, 300, 0, 0, 0), tool=(0, 0, 300, 0, 0, 0))
PITCHES_DEG = (0.0, 10.0, 20.0)
AXIS_MM = 250.0


def _platform_outline(geometry, platform_pose) -> np.ndarray:
    """The platform as a bar along its x axis, as wide as its joint circle, and the stick
    from its origin up to the tool point: (x, z) in the fixed frame."""
    transform = transform_of(platform_pose)
    radius = float(np.max(np.linalg.norm(np.array(geometry.platform_joints)[:, :2], axis=1)))
    ends = [apply(transform, (-radius, 0.0, 0.0)), apply(transform, (radius, 0.0, 0.0))]
    stick = [apply(transform, (0.0, 0.0, 0.0)), apply(transform, FRAMES.tool[:3])]
    return np.array(ends + [(np.nan,) * 3] + stick)[:, [0, 2]]


def _axes(ax, transform, label: str, colour: str) -> None:
    origin = np.array(apply(transform, (0.0, 0.0, 0.0)))
    for unit, name in (((AXIS_MM, 0.0, 0.0), "x"), ((0.0, 0.0, AXIS_MM), "z")):
        tip = np.array(apply(transform, unit))
        ax.annotate("", xy=tip[[0, 2]], xytext=origin[[0, 2]], arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.5})
        ax.text(*tip[[0, 2]], f" {name}", color=colour, fontsize=8)
    ax.text(*origin[[0, 2]] + [-40, -60], label, color=colour, fontsize=9, ha="right")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "frames.png")
    arguments = parser.parse_args(argv)
    geometry = load_geometry(default_config_path())
    home = geometry.home.in_radians()
    frames = FRAMES.frames(home)
    figure, ax = plt.subplots(figsize=(10, 6))
    base = np.array(geometry.base_joints)
    ax.plot(base[:, 0], base[:, 2], "s", color="0.3", label="base joints")
    for pitch, shade in zip(PITCHES_DEG, ("tab:blue", "tab:orange", "tab:green")):
        pose = frames.platform_pose(ToolInWorkMmDeg(0, 0, 0, 0, pitch, 0).in_radians())
        outline = _platform_outline(geometry, pose)
        ax.plot(outline[:, 0], outline[:, 1], "-", color=shade, lw=3, label=f"platform and tool, pitch {pitch:g}° in the work frame")
        joints = [apply(transform_of(pose), joint) for joint in geometry.platform_joints]
        for b, p in zip(geometry.base_joints, joints):
            ax.plot([b[0], p[0]], [b[2], p[2]], color=shade, lw=0.6, alpha=0.6)
    _axes(ax, transform_of((0.0,) * 6), "fixed frame", "0.2")
    _axes(ax, frames.work, "work frame", "tab:red")
    pivot = np.array(apply(frames.work, (0.0, 0.0, 0.0)))
    ax.plot(*pivot[[0, 2]], "*", color="tab:red", markersize=16, label="pivot point: the tool frame's origin")
    ax.set_aspect("equal")
    ax.set_xlabel("x, mm (fixed frame)")
    ax.set_ylabel("z, mm (fixed frame)")
    ax.set_title("tool frame 300 mm above the platform; work frame on it at the zero posture:\n"
                 "move --frame work pitch=10 turns the platform about the pivot", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(arguments.out, dpi=110)
    print(arguments.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
