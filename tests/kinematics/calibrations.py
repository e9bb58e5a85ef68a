"""Calibrations built for tests: a measured platform, compensated ones that keep the
set-points at a pose, and the implausible ones of hexactl issue 10 (finding 4)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import LegModel, leg_lengths, sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative


def measured(nominal: Geometry) -> Geometry:
    """A platform as a calibration describes it: every joint a few mm off the nominal one on
    all three axes (the nominal's all lie at z = 0, where a term in z counts for nothing)
    and the sensors' gains off by up to 1e-4."""
    rng = np.random.default_rng(7)
    return Geometry.model_validate({
        **nominal.model_dump(),
        "base_joints": (np.array(nominal.base_joints) + rng.uniform(-3.0, 3.0, (6, 3))).tolist(),
        "platform_joints": (np.array(nominal.platform_joints) + rng.uniform(-3.0, 3.0, (6, 3))).tolist(),
        "sensor_scale_errors": rng.uniform(-1e-4, 1e-4, 6).tolist(),
    })


def compensated(geometry: Geometry, pose_relative: Sequence[float], name: str, **changes: object) -> Geometry:
    """``geometry`` with ``changes`` (top-level keys) and the zero lengths chosen so that the
    set-points at ``pose_relative`` (mm, deg) are exactly those of ``geometry``."""
    data = {**geometry.model_dump(), **changes, "name": name}
    setpoints = sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, pose_relative))
    joints_only = LegModel(np.array(data["base_joints"]), np.array(data["platform_joints"]), np.zeros(6))
    lengths = leg_lengths(joints_only, absolute_from_relative(data["home"], pose_relative))
    data["zero_lengths"] = [length - setpoint for length, setpoint in zip(lengths, setpoints)]
    return Geometry.model_validate(data)


def implausible_calibrations(nominal: Geometry, pose_relative: Sequence[float]) -> dict[str, tuple[Geometry, str]]:
    """The finding's calibrations, each compensated at ``pose_relative``, with the parameter
    its refusal must name: base joints 1 m off, platform joints 300 mm off, home moved."""
    base = [[x + 1000.0, y, z] for x, y, z in nominal.base_joints]
    platform = [[x, y + 300.0, z] for x, y, z in nominal.platform_joints]
    home = list(nominal.home)
    home[0] += 200.0
    return {
        "base joints +1 m": (compensated(nominal, pose_relative, "base +1 m", base_joints=base), "base_joints[3]"),
        "platform joints +300 mm": (compensated(nominal, pose_relative, "platform +300 mm", platform_joints=platform),
                                    "platform_joints[0]"),
        "home moved": (compensated(nominal, pose_relative, "home +200 mm", home=home), "home[0:3]"),
    }
