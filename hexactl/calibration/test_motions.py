"""The paper's test motions (section 4): the one definition of their waypoints.

The controller's built-in test sequences, the simulated validation and the calibration
report all read these; poses are relative to the zero posture, mm and deg.
"""

from __future__ import annotations

from dataclasses import dataclass

from hexactl.kinematics.axes import RelativeMmDeg


@dataclass(frozen=True, slots=True)
class TestMotion:
    """A named list of waypoints (relative poses, mm and deg).

    ``axis`` is the pose axis the motion sweeps (index into x, y, z, roll, pitch, yaw), or
    None for a motion that moves several axes at once.
    """

    __test__ = False  # not a pytest test class, despite the name

    name: str
    title: str
    waypoints: tuple[RelativeMmDeg, ...]
    axis: int | None


def _single_axis(axis: int, values: tuple[float, ...]) -> tuple[RelativeMmDeg, ...]:
    return tuple(RelativeMmDeg._make(value if i == axis else 0.0 for i in range(6)) for value in values)


X_SWEEP = TestMotion(
    name="x_sweep",
    title="Translate in X (paper Fig. 3)",
    waypoints=_single_axis(0, (600.0, 450.0, 300.0, 150.0, 0.0, -150.0, -300.0, -450.0, -600.0)),
    axis=0,
)

Y_ROTATION = TestMotion(
    name="y_rotation",
    title="Rotate about Y (paper Fig. 4)",
    waypoints=_single_axis(4, (20.0, 15.0, 10.0, 5.0, 0.0, -5.0, -10.0, -15.0, -20.0)),
    axis=4,
)

COMPOUND = TestMotion(
    name="compound",
    title="Compound motion (paper Table 1)",
    waypoints=(RelativeMmDeg(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), RelativeMmDeg(100.0, 100.0, 100.0, 5.0, 5.0, 5.0)),
    axis=None,
)

PAPER_TEST_MOTIONS: tuple[TestMotion, ...] = (X_SWEEP, Y_ROTATION, COMPOUND)

PAPER_TABLE_1: dict[str, RelativeMmDeg] = {
    "instruction": RelativeMmDeg(100.0, 100.0, 100.0, 5.0, 5.0, 5.0),
    "before calibration": RelativeMmDeg(99.95, 99.66, 99.31, 4.94, 5.22, 5.51),
    "after calibration": RelativeMmDeg(100.29, 99.79, 100.15, 5.02, 5.06, 5.06),
}
"""The paper's measured compound-motion result (its platform, not ours), for reference."""

PAPER_MAX_STROKE_ERROR: tuple[float, float] = (0.026, 0.0035)
"""The paper's largest pose error over its X sweep and Y rotation as a fraction of the
single-axis stroke (section 4): 2.6 % before calibration (on roll, rotating about Y),
0.35 % after (on X, moving along X)."""

PAPER_STROKES: tuple[tuple[str, float], ...] = (
    ("x", 600.0), ("y", 600.0), ("z", 250.0), ("roll", 23.0), ("pitch", 23.0), ("yaw", 60.0)
)
"""Single-axis strokes of the paper's platform (mm, deg): ``hexactl check``'s default poses
are ± each, and ``hexactl demo`` reports its errors as a share of them."""
