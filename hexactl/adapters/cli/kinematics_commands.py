"""``hexactl check``, ``ik`` and ``fk``: the kinematics on the active geometry.

The kinematics (numpy) load in the functions that run the commands: declaring them must
not slow every other command's start (see :mod:`hexactl.adapters.cli.common`).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from math import isfinite
from typing import TYPE_CHECKING

from hexactl.adapters.cli.common import (
    LEG_LABELS,
    CliError,
    load_config,
    parse_numbers,
    pose_argument,
)
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS, validate_pose_values

if TYPE_CHECKING:  # the kinematics (numpy) load in the functions that run the commands
    from hexactl.kinematics.geometry import Geometry
    from hexactl.kinematics.workspace import PoseAssessment


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    output = argparse.ArgumentParser(add_help=False)
    output.add_argument("--json", action="store_true", help="machine-readable output")
    check = subparsers.add_parser(
        "check",
        parents=[common, output],
        help="reachability of poses, with margins to every limit",
        description="Check poses (relative to the zero posture) against stroke, joint-cone, "
        "pose-envelope and singularity limits. Default: the paper's single-axis extremes "
        "(X/Y ±600 mm, Z ±250 mm, roll/pitch ±23°, yaw ±60°). Exit status 1 if any is unreachable.",
        epilog="POSE is X,Y,Z,ROLL,PITCH,YAW (mm, deg) or axis=value pairs such as x=600 or "
        "pitch=-20,yaw=5. A pose may start with a minus sign (check -600,0,0,0,0,0).",
    )
    check.add_argument("poses", nargs="*", metavar="POSE", type=pose_argument)
    check.set_defaults(run=run_check)

    ik = subparsers.add_parser(
        "ik",
        parents=[common, output],
        help="leg lengths and sensor set-points for a pose",
        description="Inverse kinematics: leg lengths and actuator sensor set-points (mm) for a pose "
        "relative to the zero posture. Exit status 1 if the pose violates a limit.",
    )
    for axis, unit in zip(POSE_AXES, POSE_UNITS):
        ik.add_argument(axis.upper(), help=unit)
    ik.set_defaults(run=run_ik)

    fk = subparsers.add_parser(
        "fk",
        parents=[common, output],
        help="the pose for six sensor readings",
        description="Forward kinematics: the pose (relative to the zero posture) at which the six "
        "actuators read L1..L6 mm, and the Jacobian condition there. Exit status 1 if it does not "
        "converge, or if the pose is near-singular (condition above [limits] max_jacobian_condition): "
        "there, other poses have almost the same leg lengths and the one found may not be the platform's.",
    )
    for label in LEG_LABELS:
        fk.add_argument(label, help="sensor reading, mm")
    fk.set_defaults(run=run_fk)


def paper_extremes() -> list[list[float]]:
    from hexactl.calibration.test_motions import PAPER_STROKES

    poses = []
    for axis, stroke in PAPER_STROKES:
        for sign in (1.0, -1.0):
            pose = [0.0] * 6
            pose[POSE_AXES.index(axis)] = sign * stroke
            poses.append(pose)
    return poses


def run_check(arguments: argparse.Namespace) -> int:
    from hexactl.kinematics.workspace import assess_poses

    geometry = load_config(arguments)
    assessments = assess_poses(geometry, arguments.poses or paper_extremes())
    if arguments.json:
        print(json.dumps([_assessment_record(a) for a in assessments], indent=2))
    else:
        _print_check(geometry, assessments)
    return 0 if all(a.ok for a in assessments) else 1


def _assessment_record(assessment: PoseAssessment) -> dict[str, object]:
    return {
        "pose": list(assessment.pose_relative),
        "reachable": assessment.ok,
        "sensor_mm": list(assessment.sensor_mm),
        "stroke_margin_mm": list(assessment.stroke_margin_mm),
        "base_cone_deg": list(assessment.base_cone_deg),
        "platform_cone_deg": list(assessment.platform_cone_deg),
        "pose_margin": list(assessment.pose_margin),
        "jacobian_condition": assessment.jacobian_condition,
        "violations": [{"kind": str(v.kind), "leg": v.leg, "axis": v.axis, "value": v.value,
                        "limit": v.limit, "message": v.message} for v in assessment.violations],
    }


def _margin(margin: float) -> str:
    """A margin to one decimal; a hair beyond its bound with two significant digits, not "-0.0"."""
    return f"{margin:.1f}" if abs(margin) >= 0.05 or margin == 0 else f"{margin:.2g}"


def _print_check(geometry: Geometry, assessments: Sequence[PoseAssessment]) -> None:
    limits = geometry.limits
    print(f"geometry: {geometry.name or 'unnamed'}  stroke {limits.stroke[0]:g}..{limits.stroke[1]:g} mm, "
          f"cones base {limits.base_cone_deg:g}° platform {limits.platform_cone_deg:g}°, "
          f"condition ≤ {limits.max_jacobian_condition:g}")
    print(f"{'pose (mm, deg)':<36} {'result':<11} {'stroke margin':>15} {'base cone':>10} "
          f"{'plat. cone':>10} {'cond.':>6} {'envelope margin':>17}")
    for a in assessments:
        stroke_leg = min(range(6), key=lambda leg: a.stroke_margin_mm[leg])
        pose = ",".join(repr(v).removesuffix(".0") for v in a.pose_relative)  # as typed: 610.0001 was "610"
        # The axis nearest its bound for its envelope's size, in its own unit: the least of mm and
        # deg together (10 mm on x, 1 deg on roll printed "1.0") named no axis and mixed units.
        axis = min(range(6), key=lambda n: a.pose_margin[n] / max(limits.pose_max[n] - limits.pose_min[n], 1e-9))
        envelope = f"{POSE_AXES[axis]} {_margin(a.pose_margin[axis])} {POSE_UNITS[axis]}"
        print(f"{pose:<36} {'reachable' if a.ok else 'UNREACHABLE':<11} "
              f"{_margin(a.stroke_margin_mm[stroke_leg]):>8} mm L{stroke_leg + 1} "
              f"{max(a.base_cone_deg):>9.1f}° {max(a.platform_cone_deg):>9.1f}° "
              f"{a.jacobian_condition:>6.1f} {envelope:>17}")
        for violation in a.violations:
            print(f"    {violation.message}")
    unreachable = sum(not a.ok for a in assessments)
    print(f"{len(assessments) - unreachable} of {len(assessments)} poses reachable"
          + ("" if not unreachable else f"; {unreachable} unreachable"))


def run_ik(arguments: argparse.Namespace) -> int:
    from hexactl.kinematics.inverse import leg_lengths, readings_from_lengths
    from hexactl.kinematics.pose import absolute_from_relative
    from hexactl.kinematics.workspace import assess_poses

    geometry = load_config(arguments)
    pose = parse_numbers([getattr(arguments, axis.upper()) for axis in POSE_AXES], POSE_AXES)
    if problem := validate_pose_values(pose):  # as check and move: 1e308 overflowed to lengths of inf
        raise CliError(problem)
    lengths = leg_lengths(geometry.legs, absolute_from_relative(geometry.home, pose))
    setpoints = readings_from_lengths(geometry.legs, lengths).tolist()
    assessment = assess_poses(geometry, [pose])[0]
    if arguments.json:
        print(json.dumps({"pose": pose, "leg_lengths_mm": lengths, "setpoints_mm": setpoints,
                          "reachable": assessment.ok,
                          "violations": [v.message for v in assessment.violations]}, indent=2))
    else:
        print(f"{'leg':<4} {'length mm':>12} {'set-point mm':>13}")
        for leg, (length, setpoint) in enumerate(zip(lengths, setpoints), start=1):
            print(f"L{leg:<3} {length:>12.4f} {setpoint:>13.4f}")
        for violation in assessment.violations:
            print(f"refused: {violation.message}")
    return 0 if assessment.ok else 1


def run_fk(arguments: argparse.Namespace) -> int:
    from hexactl.kinematics.forward import forward_kinematics
    from hexactl.kinematics.inverse import lengths_from_readings
    from hexactl.kinematics.pose import relative_from_absolute
    from hexactl.kinematics.workspace import ViolationKind, assess_poses, jacobian_condition, near_singular

    geometry = load_config(arguments)
    readings = parse_numbers([getattr(arguments, label) for label in LEG_LABELS], LEG_LABELS)
    lengths = lengths_from_readings(geometry.legs, readings).tolist()
    result = forward_kinematics(geometry.legs, lengths, geometry.home.in_radians())
    pose = [float(v) for v in relative_from_absolute(geometry.home, result.pose)]
    low, high = geometry.limits.stroke
    warnings = [f"{label} {reading:g} mm is outside the stroke [{low:g}, {high:g}] mm"
                for label, reading in zip(LEG_LABELS, readings) if not low <= reading <= high]
    condition = jacobian_condition(geometry, result.pose) if result.ok else None
    singular = condition is not None and near_singular(condition, geometry.limits)
    if result.ok:  # the stroke is said of the readings above, the condition below: the joints' and the pose's limits
        warnings += [f"outside the workspace: {violation.message}" for violation in assess_poses(geometry, [pose])[0].violations
                     if violation.kind in (ViolationKind.BASE_CONE, ViolationKind.PLATFORM_CONE, ViolationKind.POSE_RANGE)]
    if singular:
        warnings.append(f"near-singular: Jacobian condition {condition:.1f} > {geometry.limits.max_jacobian_condition:g} "
                        "([limits] max_jacobian_condition); other poses (another assembly mode) have almost these "
                        "leg lengths, so this one may be tens of mm from the platform's: do not rely on it")
    if arguments.json:
        print(json.dumps({"pose": pose if result.ok else None, "status": result.status.name.lower(),
                          "iterations": result.iterations,
                          "residual_mm": result.residual_mm if isfinite(result.residual_mm) else None,  # JSON has no inf
                          "jacobian_condition": condition, "near_singular": singular,
                          "warnings": warnings}, indent=2))
    elif result.ok:
        print("  ".join(f"{axis} {value:.4f} {unit}" for axis, value, unit in zip(POSE_AXES, pose, POSE_UNITS)))
        print(f"converged in {result.iterations} iterations, residual {result.residual_mm:.1e} mm, "
              f"Jacobian condition {condition:.1f} (limit {geometry.limits.max_jacobian_condition:g})")
    else:
        print(f"no pose: forward kinematics {result.status.name.lower().replace('_', ' ')} after "
              f"{result.iterations} iterations (residual {result.residual_mm:.3g} mm)")
    for warning in warnings if not arguments.json else ():
        print(f"warning: {warning}")
    return 0 if result.ok and not singular else 1
