from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hexactl.kinematics.points import DegeneratePointsError, pose_from_points
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_matrix

from .strategies import relative_poses


def _measure(model: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return model @ rotation_matrix(*pose[3:]).T + pose[:3]


@given(relative_poses(), st.integers(3, 6), st.integers(0, 2**32 - 1))
def test_pose_from_exact_points_recovers_the_pose(nominal, pose_rel, count, seed) -> None:
    rng = np.random.default_rng(seed)
    model = np.array(nominal.measurement.feature_points)
    model = np.vstack([model, rng.uniform(-800, 800, size=(count - 3, 3))])
    pose = absolute_from_relative(nominal.home, pose_rel)
    fit = pose_from_points(model, _measure(model, pose))
    np.testing.assert_allclose(fit.pose, pose, atol=1e-9)
    assert fit.rms_mm < 1e-9 and fit.max_distance_error_mm < 1e-9


def test_noise_shows_in_the_residual_and_a_bad_point_in_the_distances(nominal) -> None:
    model = np.array(nominal.measurement.feature_points)
    pose = absolute_from_relative(nominal.home, [100.0, -50.0, 20.0, 3.0, -4.0, 10.0])
    measured = _measure(model, pose)
    measured[1] += [5.0, 0.0, 0.0]
    fit = pose_from_points(model, measured)
    assert fit.rms_mm > 1.0
    worst_pairs = np.argsort(-np.abs(fit.distance_errors_mm))[:2]
    assert set(worst_pairs) == {0, 2}  # pairs (1,2) and (2,3) contain the displaced point 2


def test_collinear_or_too_few_points_are_refused(nominal) -> None:
    line = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [300.0, 0.0, 0.0]])
    with pytest.raises(DegeneratePointsError, match="collinear"):
        pose_from_points(line, line + [0.0, 0.0, 2000.0])
    good = np.array(nominal.measurement.feature_points)
    with pytest.raises(DegeneratePointsError, match="collinear"):
        pose_from_points(good, np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]))
    with pytest.raises(DegeneratePointsError, match="at least three"):
        pose_from_points(good[:2], good[:2])
    with pytest.raises(ValueError, match="finite"):
        pose_from_points(good, np.full((3, 3), np.nan))
