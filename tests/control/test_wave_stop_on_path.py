"""A stopped or aborted wave comes to rest on the path it was validated on.

A wave has no goal: the generator's per-axis halt, handed a circle's state (velocity and
acceleration pointing different ways), braked off the path, beyond the amplitude (roll at
rest 3.62° on a 3° wave; below a leg's stroke from z = -250 mm; beyond the ±24°
envelope). The wave player now brakes along the path itself, slowing the wave's time to
a stop within the motion limits. Simulated time, ideal actuators: no wall clock.
"""

from __future__ import annotations

from math import acos, cos, degrees

import numpy as np
import pytest

from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.wave_player import WavePhase
from hexactl.control.waves import WavePath, WaveSpec
from hexactl.kinematics.axes import ToolInWorkMmRad
from hexactl.kinematics.frames import apply, transform_of
from hexactl.kinematics.soft_limits import SoftLimits
from hexactl.kinematics.workspace import check_poses

PERIOD_S = 0.002  # the default loop's


def _circle(amplitude: float, frequency: float, cycles: int = 4, frame: Frame = Frame.ZERO) -> WaveSpec:
    return WaveSpec(frame=frame, frequency_hz=frequency, cycles=cycles,
                    axes={"roll": {"amplitude": amplitude}, "pitch": {"amplitude": amplitude, "phase_deg": 90}})


def _tilt_deg(pose) -> float:
    return degrees(acos(min(1.0, cos(pose[3]) * cos(pose[4]))))


def _stop_at(rig, spec: WaveSpec, periods: float, abort: bool = False):
    """Play ``spec`` from rest, stop (or abort) it ``periods`` in; the wave's path, the
    commanded poses from a few cycles before the stop to rest, and the cycle of the stop
    in them."""
    s = rig.controller.snapshot
    start = s.trajectory.position
    if spec.frame is not Frame.ZERO:
        frames = rig.controller.operator_frames().frames(s.active.home)
        start = ToolInWorkMmRad._make(frames.tool_in_work(np.asarray(s.active.home) + np.asarray(start)))
    result = rig.controller.wave(spec)
    assert result.ok, result.message
    path = WavePath(spec, start, PERIOD_S)
    rig.run(round(periods / spec.frequency_hz / PERIOD_S) - 3)
    poses = []
    for _ in range(3):
        rig.run()
        poses.append(rig.controller.snapshot.pose_command)
    assert rig.controller.snapshot.wave.playing
    assert (rig.controller.abort() if abort else rig.controller.stop()).ok
    stop_index = len(poses) - 1
    rig.run()
    s = rig.controller.snapshot
    assert s.wave.phase is WavePhase.ABORTED
    assert s.motion.value == "stopping"
    end_ns = s.motion_end_ns
    while True:
        poses.append(rig.controller.snapshot.pose_command)
        if rig.controller.snapshot.motion.value == "holding":
            break
        rig.run()
        assert len(poses) < path.samples, "the brake did not end"
    # the time to rest reported when the brake started is when it came to rest
    assert abs(rig.controller.snapshot.t_ns - end_ns) <= rig.period_ns
    assert rig.controller.snapshot.wave.phase is WavePhase.ABORTED
    return path, np.array(poses), stop_index


def _assert_on_path(path: WavePath, rest) -> None:
    samples = np.array([path.at(k) for k in range(path.samples + 1)])
    assert np.min(np.max(np.abs(samples - np.asarray(rest)), axis=1)) < 1e-9, "at rest off the wave's path"


def _assert_within_braking_limits(rig, poses: np.ndarray, stop_index: int) -> None:
    """Velocity, acceleration and jerk of the commanded poses from the stop on within the
    motion limits (the wave itself was validated within them): no jump anywhere."""
    velocity, acceleration, jerk = rig.controller.config.motion.in_mm_rad()
    segment = poses[max(0, stop_index - 2):]
    for order, limit, slack in ((1, velocity, 1.001), (2, acceleration, 1.01), (3, jerk, 1.05)):
        peaks = np.abs(np.diff(segment, n=order, axis=0)).max(axis=0) / PERIOD_S**order
        assert np.all(peaks <= np.asarray(limit) * slack), (order, peaks, limit)
    # braking: the speed at rest is zero and it does not grow again towards the end
    speed = np.linalg.norm(np.diff(segment[2:], axis=0), axis=1)
    assert speed[-1] < 1e-6
    tail = speed[len(speed) // 2:]
    assert np.all(np.diff(tail) <= 1e-12)


@pytest.mark.parametrize("k", range(12))
def test_a_circle_wave_stopped_anywhere_rests_on_its_path_inside_the_soft_tilt(rig, k):
    limit = 3.01
    assert rig.controller.set_frames(OperatorFrames(soft_limits=SoftLimits(lower=[None] * 6, upper=[None] * 6,
                                                                           max_tilt_deg=limit))).ok
    rig.enabled()
    spec = _circle(3.0, 0.45)
    path, poses, stop_index = _stop_at(rig, spec, 1.5 + k / 12, abort=k % 2 == 1)
    rest = poses[-1]
    _assert_on_path(path, rest)
    assert max(_tilt_deg(p) for p in poses) <= 3.0 + 1e-9
    assert max(np.abs(np.degrees(poses[:, 3:5])).max(axis=0)) <= 3.0 + 1e-9  # no axis beyond its amplitude
    _assert_within_braking_limits(rig, poses, stop_index)
    assert rig.controller.telemetry().loop.guard_clamps == 0
    assert rig.controller.snapshot.trajectory.resting
    rig.assert_setpoints_safe()
    # inside the validated limits: a move back is not refused
    assert rig.controller.move([0, 0, 0, 0, 0, 0]).ok
    rig.settle()


@pytest.mark.parametrize("periods", [1.7, 1.45, 2.2])
def test_a_wave_bound_by_the_stroke_stopped_rests_inside_it(make_rig, geometry, periods):
    """From z = -250 mm, the largest circle validate_wave accepts (the legs' stroke binds)."""
    rig = make_rig(start_pose=(0, 0, -250, 0, 0, 0)).enabled()
    assert rig.controller.validate_wave(_circle(8.749, 0.15)).ok
    path, poses, stop_index = _stop_at(rig, _circle(8.749, 0.15), periods)
    _assert_on_path(path, poses[-1])
    low, high = geometry.limits.stroke
    sent = rig.sent
    assert sent.min() >= low and sent.max() <= high
    assert rig.controller.telemetry().loop.guard_clamps == 0
    assert not check_poses(geometry, np.array([[*poses[-1][:3], *np.degrees(poses[-1][3:])]])).broken.any()
    _assert_within_braking_limits(rig, poses, stop_index)
    rig.assert_setpoints_safe()


@pytest.mark.parametrize("periods", [1.3, 1.55, 1.8])
def test_a_wave_near_the_envelope_stopped_rests_inside_it(rig, geometry, periods):
    rig.enabled()
    spec = _circle(23.9, 0.06, cycles=3)
    assert rig.controller.validate_wave(spec).ok
    path, poses, stop_index = _stop_at(rig, spec, periods)
    _assert_on_path(path, poses[-1])
    assert np.degrees(np.abs(poses[:, 3:5])).max() <= 23.9 + 1e-9
    assert not check_poses(geometry, np.array([[*p[:3], *np.degrees(p[3:])] for p in poses])).broken.any()
    assert rig.controller.telemetry().loop.guard_clamps == 0
    _assert_within_braking_limits(rig, poses, stop_index)


def test_a_tool_frame_wave_brakes_along_its_path_about_the_pivot(rig):
    tool_above = OperatorFrames(work=(0, 0, 300, 0, 0, 0), tool=(0, 0, 300, 0, 0, 0))
    assert rig.controller.set_frames(tool_above).ok
    rig.enabled()
    s = rig.controller.snapshot
    pivot_in_platform = tool_above.frames(s.active.home).tool.translation
    home = np.asarray(s.active.home)
    before = apply(transform_of(home + np.asarray(s.pose_command)), pivot_in_platform)
    spec = _circle(2.0, 0.5, frame=Frame.TOOL)
    path, poses, stop_index = _stop_at(rig, spec, 1.6)
    deviations = [np.linalg.norm(np.subtract(apply(transform_of(home + p), pivot_in_platform), before)) for p in poses]
    assert max(deviations) < 1e-3  # the pivot stays put while braking too: the brake is on the tool frame's path
    frames = tool_above.frames(s.active.home)
    rest_in_work = frames.tool_in_work(home + poses[-1])
    _assert_on_path(path, rest_in_work)
    assert rig.controller.telemetry().loop.guard_clamps == 0


def test_a_move_during_the_brake_takes_over_from_where_the_brake_is(rig):
    rig.enabled()
    spec = _circle(3.0, 0.45)
    assert rig.controller.wave(spec).ok
    rig.run(round(1.6 / 0.45 / PERIOD_S))
    assert rig.controller.stop().ok
    rig.run(10)
    assert rig.controller.snapshot.motion.value == "stopping"
    assert rig.controller.move([0, 0, 0, 0, 0, 0]).ok
    rig.settle()
    s = rig.controller.snapshot
    assert np.allclose(s.pose_command, 0.0, atol=1e-12) and s.trajectory.resting
    assert s.wave.phase is WavePhase.ABORTED
    assert rig.controller.telemetry().loop.guard_clamps == 0
    rig.assert_setpoints_safe()
