"""The bounds the controller puts on a motion's numbers (a move's duration, a wave's
frequency, cycles, amplitudes and phase, a jog's velocity), stated once: the planner and the models check
them, and the CLI refuses an option beyond them before it asks. Standard library only
here: the CLI reads it."""

from collections.abc import Sequence

MAX_MOTION_S = 600.0
"""The longest motion one plan may hold, s: a move, or a sequence's moves together (dwells
not counted). Planning samples every loop period, so its work grows with the motion's
length and its path's (BENCHMARKS.md, "Planning long motion";
:data:`~hexactl.control.planning.PLANNING_BUDGET_S` bounds it at load); no posture of a
calibration campaign takes a tenth of it."""

MAX_FREQUENCY_HZ = 50.0
"""The fastest wave: ten loop cycles a period at the default 500 Hz."""
MAX_CYCLES = 1_000_000
"""A bound that keeps a wave's count a number; its duration is capped by :data:`MAX_MOTION_S`."""
MAX_AMPLITUDE_MM = 1000.0
MAX_AMPLITUDE_DEG = 90.0
MAX_PHASE_DEG = 360.0
"""A wave axis's phase at the start is within ±this, deg."""
MAX_JOG_VELOCITY = 1e4
"""Bigger jog velocity components (mm/s, deg/s) are typing errors; the motion limits cap the rest."""
MIN_JOG_VELOCITY = 1e-6
"""A jog whose every component (mm/s, deg/s) is smaller, and not all zero (a release), moves
less than a nanometre a second: a rounding residue, not a velocity."""


def amplitude_problem(axis: str, amplitude: float) -> str | None:
    """What is wrong with a wave's ``amplitude`` on ``axis`` (mm for x, y, z; deg for
    roll, pitch, yaw), or None."""
    bound, unit = (MAX_AMPLITUDE_MM, "mm") if axis in ("x", "y", "z") else (MAX_AMPLITUDE_DEG, "deg")
    if not abs(amplitude) <= bound:
        return f"{axis} amplitude {amplitude:g} {unit} is beyond ±{bound:g} {unit}"
    return None


def ramp_problem(ramp_cycles: float, cycles: int) -> str | None:
    """What is wrong with a wave of ``cycles`` periods ramped in, and again out, over
    ``ramp_cycles`` periods each (its ramp first, as in its message), or None."""
    if 2 * ramp_cycles > cycles:
        return f"{ramp_cycles:g} ramps in and again out: at most half of cycles ({cycles}); lower it or add cycles"
    return None


def jog_velocity_problem(velocity: Sequence[float]) -> str | None:
    """What is wrong with a jog's ``velocity`` (six finite numbers, mm/s and deg/s), or None."""
    for value in velocity:
        if abs(value) > MAX_JOG_VELOCITY:
            return (f"a jog velocity component of {value:.12g} is beyond {MAX_JOG_VELOCITY:g} (mm/s or deg/s): a "
                    "typing error?")
    if 0 < (fastest := max(map(abs, velocity))) < MIN_JOG_VELOCITY:
        return (f"a jog velocity of at most {fastest:.3g} (mm/s or deg/s) is too slow to move: at least "
                f"{MIN_JOG_VELOCITY:g} on one axis, or all zeros to release")
    return None
