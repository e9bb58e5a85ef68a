"""Hypothesis strategies shared by the kinematics tests."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st


def relative_poses(scale: float = 1.0) -> st.SearchStrategy[list[float]]:
    """Poses relative to the zero posture inside the paper's single-axis strokes (mm, deg),
    scaled down so that combined axes stay reachable."""
    bounds = np.array([600.0, 600.0, 250.0, 23.0, 23.0, 60.0]) * scale
    return st.tuples(*(st.floats(-b, b, allow_nan=False) for b in bounds)).map(list)
