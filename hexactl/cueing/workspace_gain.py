"""Fitting a cue into the platform's workspace: the workspace-aware gain and the limiter.

Reachability is hexactl's own (:func:`hexactl.kinematics.workspace.assess_poses`: stroke,
joint cones, pose envelope, singularity) on the geometry given, calibrated or nominal.
Each pose assessed costs a fraction of a millisecond, so both pieces work on a whole
planned trajectory offline, assessing batches of poses:

- :func:`gain_to_fill_workspace`: the largest gain on the washout's onset channels (its
  high-passed translation and rotation) with every pose of the trajectory using at most
  :attr:`~hexactl.cueing.parameters.WorkspaceUse.use_fraction` of the workspace. The tilt
  coordination is not scaled: it reproduces the sustained specific force one to one,
  and scaled up it would overstate it and turn faster than its rate limit.
- :func:`limit_to_workspace`: every pose whose use is above the knee is pulled toward the
  zero posture along the line to it, by a smooth saturation of its use, so that none is
  beyond the ceiling; continuous, and never faster than the pose it follows along that line.

A pose's *use* of the workspace is ``|p| / reach`` along its ray from the zero posture:
the fraction of the way to the first limit on the straight line in pose space (mm and
deg) through it. The pieces rely on the reachable poses along each ray forming one
segment from the zero posture (true of this kind of platform near its zero posture);
:func:`limit_to_workspace` verifies every pose it returns, so a workspace where that
fails is an error, never an unreachable pose.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from hexactl.cueing.parameters import WorkspaceUse
from hexactl.cueing.washout import WashoutChannels
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import assess_pose, assess_poses

RAY_BISECTIONS = 17
"""Halvings of a ray's reach interval: the reach to 2⁻¹⁷ (8e-6) of the envelope's extent
along it, a few µm or thousandths of a degree."""

GAIN_RESOLUTION = 1e-3
"""The gain is found to this, whatever ``max_gain`` (a fixed number of halvings of
[0, max_gain] would lose the gain of a large one)."""

GAIN_CANDIDATES = 150
"""Samples a gain is first searched over (evenly spread, plus each axis's extremes);
then every sample is checked at the gain found, and any that fails joins the search."""


class WorkspaceError(ValueError):
    """A limited pose is not reachable: the workspace is not one segment along its ray."""


def reachable(geometry: Geometry, poses: NDArray) -> NDArray[np.bool_]:
    """For each of (N, 6) poses relative to the zero posture (mm, deg): within every limit."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    return np.array([assessment.ok for assessment in assess_poses(geometry, poses)])


def ray_reach(geometry: Geometry, poses: NDArray) -> NDArray[np.float64]:
    """For each of (N, 6) poses (relative mm/deg), the largest scale s, to
    :data:`RAY_BISECTIONS`, with s·pose reachable (verified): its use of the workspace is
    1/s. ``inf`` for the zero pose."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    low = np.zeros(len(poses))
    high = _envelope_scale(geometry, poses)  # beyond it the pose envelope is left
    moving = np.isfinite(high)
    at_envelope = reachable(geometry, poses[moving] * high[moving, None])
    low[moving] = np.where(at_envelope, high[moving], 0.0)
    searching = np.flatnonzero(moving)[~at_envelope]
    for _ in range(RAY_BISECTIONS):
        middle = (low[searching] + high[searching]) / 2.0
        ok = reachable(geometry, poses[searching] * middle[:, None])
        low[searching] = np.where(ok, middle, low[searching])
        high[searching] = np.where(ok, high[searching], middle)
    low[~moving] = np.inf
    return low


def _envelope_scale(geometry: Geometry, poses: NDArray) -> NDArray[np.float64]:
    """The scale at which each pose meets the pose envelope; ``inf`` for the zero pose."""
    upper, lower = np.array(geometry.limits.pose_max), np.array(geometry.limits.pose_min)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a tiny component: no bound
        scales = np.where(poses > 0, upper / poses, np.where(poses < 0, lower / poses, np.inf))
    return scales.min(axis=1)


def gain_to_fill_workspace(geometry: Geometry, channels: WashoutChannels, workspace: WorkspaceUse) -> float:
    """The largest gain g in [0, ``workspace.max_gain``] (to :data:`GAIN_RESOLUTION`) with
    every pose ``channels.poses(g)`` using at most ``workspace.use_fraction`` of the
    workspace. 0 when the tilt alone uses more somewhere (then only the limiter fits the
    cue: lower ``tilt.limit_deg``)."""
    ceiling = workspace.use_fraction

    def fits(gain: float, samples: NDArray[np.intp]) -> NDArray[np.bool_]:
        return reachable(geometry, (channels.tilt[samples] + gain * channels.onset[samples]) / ceiling)

    everything = np.arange(len(channels.onset))
    candidates = _gain_candidates(channels, workspace.max_gain)
    while True:
        # samples=candidates: this round's set, bound now (the set grows between rounds)
        gain = _largest_fitting_gain(lambda g, samples=candidates: bool(np.all(fits(g, samples))), workspace.max_gain)
        if gain == 0.0:
            return gain
        failing = everything[~fits(gain, everything)]
        if len(failing) == 0:
            return gain
        candidates = np.union1d(candidates, failing)


def _gain_candidates(channels: WashoutChannels, gain: float) -> NDArray[np.intp]:
    """Evenly spread samples and, at ``gain``, each axis's largest and smallest."""
    poses = channels.poses(gain)
    spread = np.linspace(0, len(poses) - 1, min(len(poses), GAIN_CANDIDATES)).round().astype(np.intp)
    return np.union1d(spread, np.concatenate([poses.argmax(axis=0), poses.argmin(axis=0)]))


def _largest_fitting_gain(fits: Callable[[float], bool], max_gain: float) -> float:
    """Bisection for the largest gain in [0, max_gain] that ``fits`` (true up to some
    gain, false beyond); 0 if none does."""
    if fits(max_gain):
        return max_gain
    if not fits(0.0):
        return 0.0
    low, high = 0.0, max_gain
    while high - low > GAIN_RESOLUTION:
        middle = (low + high) / 2.0
        low, high = (middle, high) if fits(middle) else (low, middle)
    return low


def soft_saturation(use: NDArray, knee: float, ceiling: float) -> NDArray[np.float64]:
    """The limited use of each use of the workspace: itself up to ``knee``, above it
    ``knee + (ceiling − knee)·tanh((use − knee)/(ceiling − knee))``, which leaves the knee
    with slope 1 (no kink), never falls and never reaches ``ceiling``."""
    use = np.asarray(use, dtype=float)
    band = ceiling - knee
    return np.where(use <= knee, use, knee + band * np.tanh((use - knee) / band))


def limit_to_workspace(geometry: Geometry, poses: NDArray, workspace: WorkspaceUse) -> NDArray[np.float64]:
    """(N, 6) poses (relative mm/deg), each whose use of the workspace is above
    ``workspace.limiter_knee`` scaled toward the zero posture to the use
    :func:`soft_saturation` gives it, at most ``workspace.limiter_ceiling``; the others
    unchanged. A continuous function of the pose, and along the ray never steeper than 1.

    :class:`WorkspaceError` if a returned pose would not be reachable (the workspace is not
    one segment along its ray); every returned pose is checked."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    limited = poses.copy()
    beyond_knee = ~reachable(geometry, poses / workspace.limiter_knee)
    if beyond_knee.any():
        with np.errstate(divide="ignore"):  # reach 0, no step from the zero posture fits: use inf, pose 0
            use = 1.0 / ray_reach(geometry, poses[beyond_knee])
        saturated = soft_saturation(use, workspace.limiter_knee, workspace.limiter_ceiling)
        limited[beyond_knee] = poses[beyond_knee] * (saturated / use)[:, None]
    unreachable = np.flatnonzero(~reachable(geometry, limited))
    if len(unreachable):
        first = unreachable[0]
        raise WorkspaceError(
            f"{len(unreachable)} limited poses are not reachable, the first sample {first}: "
            f"{np.round(limited[first], 3).tolist()} (relative mm/deg); the workspace of '{geometry.name}' is not one "
            "segment along the line from the zero posture to it")
    return limited


def stroke_use(geometry: Geometry, poses: NDArray) -> NDArray[np.float64]:
    """For each of (N, 6) poses (relative mm/deg), the largest fraction over the legs of
    the stroke margin used: how far the leg's sensor reading has moved from its reading
    at the zero posture, over the distance from there to the stroke's end it moves toward."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    low, high = geometry.limits.stroke
    neutral = np.array(assess_pose(geometry, [0.0] * 6).sensor_mm)
    readings = np.array([assessment.sensor_mm for assessment in assess_poses(geometry, poses)]).reshape(-1, 6)
    travel = readings - neutral
    room = np.where(travel >= 0, high - neutral, neutral - low)
    return np.max(np.abs(travel) / room, axis=1)
