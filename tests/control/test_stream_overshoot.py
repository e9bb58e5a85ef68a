"""A stream's target with a velocity never takes the platform beyond what its receiver
checked: ruckig, asked to pass a target at a velocity it has no room to reach ahead,
backs up first (found from outside: a sine coming back from the workspace's boundary
went 12 mm beyond it, a ramp from rest went backwards first)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hexactl.control.frames import OperatorFrames
from hexactl.kinematics.soft_limits import SoftLimits


def _opened(rig, **options):
    rig.enabled()
    reply = rig.controller.stream_open("test", **options)
    assert reply.ok, reply.message
    rig.run()


def _follow(rig, poses) -> np.ndarray:
    """Send ``poses`` (mm, deg), one a cycle; the commanded pose after each (relative mm/rad)."""
    commanded = []
    for n, pose in enumerate(poses):
        assert rig.controller.stream_target(pose, n, rig.clock.now_ns / 1e9, rig.clock.now_ns).sent
        rig.run()
        commanded.append(rig.controller.snapshot.pose_command)
    return np.array(commanded)


def test_a_stream_coming_back_from_the_boundary_does_not_overshoot_it(rig) -> None:
    """x ±1200 mm at 0.05 Hz, the envelope ±610 mm: held at rest on the boundary, the
    stream's first target back inside (at 320 mm/s) was planned backing up to 634 mm and
    the platform reached 622 mm."""
    _opened(rig)
    rate_hz = 1e9 / rig.period_ns
    t = np.arange(int(8.7 * rate_hz)) / rate_hz  # beyond +610 from 1.7 s to 8.3 s, back inside after
    x = _follow(rig, [(1200.0 * math.sin(2 * math.pi * 0.05 * s), 0, 0, 0, 0, 0) for s in t])[:, 0]
    assert x.max() == pytest.approx(610.0, abs=0.05)  # it got to the boundary
    assert x.max() <= 610.0 + 1e-6
    assert x[-1] < 600.0  # and follows the stream back inside
    assert rig.controller.snapshot.clamped_cycles == 0
    rig.assert_setpoints_safe()


def test_a_ramp_from_rest_does_not_move_backwards_first(rig) -> None:
    """+x at 300 mm/s from rest: the first target, 15.6 mm ahead at 300 mm/s, was planned
    backing up to -10.9 mm and the platform went 3.2 mm backwards."""
    _opened(rig)
    rate_hz = 1e9 / rig.period_ns
    x = _follow(rig, [(300.0 * n / rate_hz, 0, 0, 0, 0, 0) for n in range(int(0.5 * rate_hz))])[:, 0]
    assert x.min() >= -1e-6
    assert np.all(np.diff(x) >= -1e-9)  # forwards only
    assert x[-1] > 50.0


def test_a_tilt_coming_back_from_a_soft_limit_does_not_overshoot_it(rig) -> None:
    """Max tilt 5°, a roll sine ±15° at 0.25 Hz: roll reached ±5.77°."""
    assert rig.controller.set_frames(OperatorFrames(soft_limits=SoftLimits(max_tilt_deg=5.0))).ok
    _opened(rig)
    rate_hz = 1e9 / rig.period_ns
    t = np.arange(int(6 * rate_hz)) / rate_hz
    roll = np.degrees(_follow(rig, [(0, 0, 0, 15.0 * math.sin(2 * math.pi * 0.25 * s), 0, 0) for s in t])[:, 3])
    assert np.abs(roll).max() == pytest.approx(5.0, abs=0.05)
    assert np.abs(roll).max() <= 5.0 + 1e-4
    assert rig.controller.snapshot.clamped_cycles == 0
