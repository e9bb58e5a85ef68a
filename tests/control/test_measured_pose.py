"""The measured pose (forward kinematics of the feedback): at ``fk_rate_hz`` while
enabled, and fresh in every dwell record."""

from __future__ import annotations

import pytest

from hexactl.control.config import ControllerConfig
from hexactl.control.sequences import MotionSequence, SequenceWaypoint
from hexactl.kinematics.forward import forward_kinematics
from hexactl.kinematics.pose import pose_mm_rad_to_mm_deg


def measured_from(rig, positions_mm) -> tuple[float, ...]:
    """The relative mm/deg pose of these sensor readings, solved afresh."""
    geometry = rig.geometry
    lengths = [p + z for p, z in zip(positions_mm, geometry.zero_lengths)]
    home = rig.controller.snapshot.active.home
    result = forward_kinematics(geometry.legs, lengths, home)
    assert result.ok
    return tuple(float(v) for v in pose_mm_rad_to_mm_deg([a - h for a, h in zip(result.pose, home)]))


def test_enabled_and_moving_it_is_measured_at_the_stated_rate(make_rig) -> None:
    rig = make_rig(config=ControllerConfig(fk_rate_hz=100.0)).enabled()  # every 5th cycle at 500 Hz
    assert rig.controller.move([50, 0, 0, 0, 0, 0], duration=0.5).ok
    poses, cycles = [], []
    for _ in range(100):
        rig.run()
        poses.append(rig.controller.snapshot.pose_measured)
        cycles.append(rig.controller.snapshot.cycle)
    updates = [cycles[i] for i in range(1, len(poses)) if poses[i] != poses[i - 1]]
    assert len(updates) >= 15 and all(b - a == 5 for a, b in zip(updates, updates[1:])), updates


def test_every_dwell_record_has_the_pose_measured_in_its_own_cycle(make_rig) -> None:
    rig = make_rig(config=ControllerConfig(fk_rate_hz=10.0)).enabled()  # every 50th cycle: stale but for the record
    no_dwell = MotionSequence(name="no_dwell", waypoint=[SequenceWaypoint(pose=[40, 0, 0, 0, 0, 0], duration=0.3),
                                                         SequenceWaypoint(pose=[0, 30, 0, 0, 0, 2], duration=0.3)])
    assert rig.controller.play(no_dwell).ok
    rig.settle()
    records = rig.controller.sequence_records().records
    assert len(records) == 2
    for record in records:
        assert record.pose_measured == pytest.approx(measured_from(rig, record.leg_feedback), abs=1e-6)
