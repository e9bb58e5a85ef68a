"""A cue plan: a recorded vehicle trajectory turned into platform poses the platform can
reach, with the specific force they make its occupant feel (what ``hexactl cue`` streams).

The steps (docs/cueing.md): the washout filter over the whole trajectory; with the
workspace-aware gain, its onset channels scaled to use the workspace; every pose through
the limiter, which guarantees that each is reachable on ``geometry``; and the specific
force the poses produce, compared with the vehicle's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hexactl.cueing.parameters import CueingParameters
from hexactl.cueing.washout import (
    VehicleTrajectory,
    perceived_specific_force,
    rms_difference,
    wash_out,
)
from hexactl.cueing.workspace_gain import gain_to_fill_workspace, limit_to_workspace
from hexactl.kinematics.axes import RelativeMmDeg
from hexactl.kinematics.geometry import Geometry


@dataclass(frozen=True)
class CuePlan:
    """Poses to play one every ``period_s`` (s), and how well they reproduce the vehicle."""

    period_s: float
    poses: tuple[RelativeMmDeg, ...]
    """One per sample, relative to the zero posture, mm and deg; every one reachable."""
    vehicle_specific_force: NDArray[np.float64]
    """(N, 3) m/s², the vehicle's, body axes."""
    platform_specific_force: NDArray[np.float64]
    """(N, 3) m/s², what the platform's motion makes its occupant feel, platform axes."""
    gain: float
    """The workspace-aware gain applied to the onset channels (1.0 when off)."""
    rms_error: float
    """RMS over the samples of |vehicle − platform| specific force, m/s²."""


def plan_cue(vehicle: VehicleTrajectory, parameters: CueingParameters, geometry: Geometry, *,
             workspace_gain: bool = True) -> CuePlan:
    """The cue plan for ``vehicle`` on ``geometry`` (calibrated or nominal).

    ``workspace_gain`` False leaves the onset channels at gain 1, with only the limiter
    between the filter and the workspace. :class:`hexactl.cueing.workspace_gain.WorkspaceError`
    if the limiter cannot guarantee a pose (a workspace unlike a hexapod's near its zero
    posture)."""
    channels = wash_out(parameters, vehicle)
    gain = gain_to_fill_workspace(geometry, channels, parameters.workspace) if workspace_gain else 1.0
    poses = limit_to_workspace(geometry, channels.poses(gain), parameters.workspace)
    platform = perceived_specific_force(poses, vehicle.period_s)
    return CuePlan(
        period_s=vehicle.period_s,
        poses=tuple(tuple.__new__(RelativeMmDeg, pose) for pose in poses.tolist()),
        vehicle_specific_force=vehicle.specific_force,
        platform_specific_force=platform,
        gain=gain,
        rms_error=rms_difference(vehicle.specific_force, platform),
    )
