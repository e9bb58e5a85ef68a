"""Kinematics benchmarks (pytest-benchmark). Skipped in the normal run; reproduce with
``python -m pytest tests/benchmarks --benchmark-only`` and see BENCHMARKS.md."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.config_path import default_config_path
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.inverse import leg_lengths, sensor_setpoints, sensor_setpoints_batch
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.workspace import assess_pose, pose_within_limits

BATCH = 10_000


@pytest.fixture(scope="module")
def geometry():
    return load_geometry(default_config_path())


@pytest.fixture(scope="module")
def pose(geometry):
    return tuple(float(v) for v in absolute_from_relative(geometry.home, [100.0, 100.0, 100.0, 5.0, 5.0, 5.0]))


def test_ik_single_pose_plain_floats(benchmark, geometry, pose) -> None:
    """The control loop's path."""
    setpoints = benchmark(sensor_setpoints, geometry.legs, pose)
    assert len(setpoints) == 6


def test_ik_single_pose_numpy(benchmark, geometry, pose) -> None:
    """The same through the vectorised path with N = 1: the alternative the loop rejected."""
    single = np.array([pose])
    setpoints = benchmark(sensor_setpoints_batch, geometry.legs, single)
    np.testing.assert_allclose(setpoints[0], sensor_setpoints(geometry.legs, pose), atol=1e-9)


def test_ik_batch_10k_poses(benchmark, geometry) -> None:
    """Divide the mean by 10,000 for the per-pose figure."""
    rng = np.random.default_rng(1)
    relative = rng.uniform(-1, 1, size=(BATCH, 6)) * [300, 300, 120, 10, 10, 30]
    poses = absolute_from_relative(geometry.home, relative)
    setpoints = benchmark(sensor_setpoints_batch, geometry.legs, poses)
    assert setpoints.shape == (BATCH, 6)


def test_fk_warm_start_one_cycle_away(benchmark, geometry, pose) -> None:
    """The loop's case: the previous cycle's pose as guess, 0.8 mm / 0.1° away (400 mm/s at 500 Hz)."""
    lengths = leg_lengths(geometry.legs, pose)
    guess = np.add(pose, [0.8, -0.8, 0.8, 0.0017, -0.0017, 0.0017])
    result = benchmark(forward_kinematics, geometry.legs, lengths, guess)
    assert result.ok


def test_fk_cold_start_from_the_zero_posture(benchmark, geometry, pose) -> None:
    lengths = leg_lengths(geometry.legs, pose)
    home = absolute_from_relative(geometry.home, [0.0] * 6)
    result = benchmark(forward_kinematics, geometry.legs, lengths, home)
    assert result.ok


def test_workspace_yes_no_single_pose_plain_floats(benchmark, geometry) -> None:
    """A stream's per-target check: does one pose break any limit?"""
    assert benchmark(pose_within_limits, geometry, [100.0, 100.0, 100.0, 5.0, 5.0, 5.0])


def test_workspace_full_assessment_single_pose(benchmark, geometry) -> None:
    """The same pose through the full assessment (every violation, every margin): what a
    stream's check cost before it had its own."""
    assert benchmark(assess_pose, geometry, [100.0, 100.0, 100.0, 5.0, 5.0, 5.0]).ok
