"""Plausibility of a calibration: is it a measurement of the nominal platform at all?

A calibration identifies the joints and zero lengths of one physical machine, whose
design is the nominal geometry; manufacturing puts each within millimetres of its
design value. A calibration far from the nominal one is a wrong file, not a machine: it
can reproduce the set-points at the current pose exactly (zero lengths chosen to
compensate) and still send the real platform far outside its limits once it moves,
because every limit is checked on the model. So each parameter must lie within a bound
of its nominal value; the bounds are the hardware's ``[limits]`` (``calibration_*``;
their defaults and why: docs/calibration.md).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.axes import POSE_AXES


def implausibilities(geometry: Geometry, nominal: Geometry) -> list[str]:
    """Every parameter of ``geometry`` beyond its plausibility bound around ``nominal``,
    one sentence each naming the parameter, its distance, the bound and the ``[limits]``
    key (mm and deg); empty when the calibration is plausible. The bounds are
    ``nominal.limits``' (a calibration's limits must equal them anyway)."""
    limits = nominal.limits
    problems = parameter_implausibilities(geometry.base_joints, geometry.platform_joints, geometry.zero_lengths, nominal)
    shift = float(np.linalg.norm(np.subtract(geometry.home[:3], nominal.home[:3])))
    if not shift <= limits.calibration_home_tolerance_mm:
        problems.append(_beyond("home[0:3] (x, y, z)", shift, "mm", limits.calibration_home_tolerance_mm,
                                "calibration_home_tolerance_mm"))
    for i in range(3, 6):
        turn = abs(geometry.home[i] - nominal.home[i])
        if not turn <= limits.calibration_home_tolerance_deg:
            problems.append(_beyond(f"home[{i}] ({POSE_AXES[i]})", turn, "deg", limits.calibration_home_tolerance_deg,
                                    "calibration_home_tolerance_deg"))
    return problems


def parameter_implausibilities(base_joints: ArrayLike, platform_joints: ArrayLike, zero_lengths: ArrayLike,
                               nominal: Geometry) -> list[str]:
    """:func:`implausibilities` of the identified quantities alone (joints (6, 3) and zero
    lengths (6,), mm), before they are made into a geometry."""
    limits = nominal.limits
    problems = []
    for key, joints in (("base_joints", base_joints), ("platform_joints", platform_joints)):
        distances = np.linalg.norm(np.subtract(joints, getattr(nominal, key)), axis=1)
        problems += [_beyond(f"{key}[{i}] (leg {i + 1})", float(d), "mm", limits.calibration_joint_tolerance_mm,
                             "calibration_joint_tolerance_mm")
                     for i, d in enumerate(distances) if not d <= limits.calibration_joint_tolerance_mm]
    for i, (length, design) in enumerate(zip(zero_lengths, nominal.zero_lengths)):
        if not abs(length - design) <= limits.calibration_zero_length_tolerance_mm:
            problems.append(_beyond(f"zero_lengths[{i}] (leg {i + 1})", abs(length - design), "mm",
                                    limits.calibration_zero_length_tolerance_mm, "calibration_zero_length_tolerance_mm"))
    return problems


def _beyond(parameter: str, distance: float, unit: str, bound: float, key: str) -> str:
    return f"{parameter} is {distance:.1f} {unit} from the nominal (bound {bound:g} {unit}, [limits] {key})"
