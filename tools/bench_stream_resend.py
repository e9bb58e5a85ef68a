"""How a pose stream is followed whose sender resends its source's last pose until the
source updates (a 60 Hz game sent on at the loop's rate), beside senders of every sample
and a sender that stops at a pose, in simulated time (the loop stepped by hand on ideal
actuators, :mod:`simulated_stream`): the figures do not depend on the host's load.

    python3 tools/bench_stream_resend.py
    python3 tools/bench_stream_resend.py --tree /tmp/before   # a git worktree of another commit
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

SINE_MM, SINE_HZ = 100.0, 0.5  # a 100 mm, 0.5 Hz sine in x: 314 mm/s at most
SENDERS = ((500, 60), (250, 60), (100, 60), (500, 500), (100, 100), (60, 60))
"""(samples sent a second, source updates a second): a sender of every sample where equal."""


def sine(t: float) -> float:
    return SINE_MM * math.sin(2 * math.pi * SINE_HZ * t)


def commanded_x(pose_x: Callable[[float], float], send_hz: float, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and x commanded (mm) each loop cycle for a stream of x ``pose_x(t)`` (mm)
    sent ``send_hz`` times a second, stamped with its send time."""
    from simulated_stream import SimulatedStream

    stream = SimulatedStream()
    sent, times, x = 0, [], []
    while stream.time_s < seconds:
        while stream.time_s >= sent / send_hz - 1e-9:  # every sample due by now (the first few at once)
            stream.send((pose_x(sent / send_hz), 0, 0, 0, 0, 0), sent + 1, sent / send_hz)
            sent += 1
        stream.step()
        times.append(stream.time_s), x.append(stream.pose_command[0])
    return np.array(times), np.array(x)


def follow(send_hz: float, source_hz: float, seconds: float = 6.0) -> tuple[float, float]:
    """The lag (s) at which x commanded best matches the sine, and the RMS error to the sine
    itself (mm), from 1.5 s to 5.5 s."""
    t, x = commanded_x(lambda s: sine(math.floor(s * source_hz + 1e-9) / source_hz), send_hz, seconds)
    window = (t > 1.5) & (t < 5.5)
    lags = np.arange(0, 0.4, t[1] - t[0])
    errors = [np.sqrt(np.mean((x[window] - np.vectorize(sine)(t[window] - lag)) ** 2)) for lag in lags]
    return float(lags[int(np.argmin(errors))]), float(errors[0])


def stop(send_hz: float, seconds: float = 3.0) -> tuple[float, float]:
    """A ramp of x at 200 mm/s that stops at 200 mm after 1 s, each sample its own: the
    farthest x went (mm) and where it came to rest."""
    _, x = commanded_x(lambda s: 200.0 * min(s, 1.0), send_hz, seconds)
    return float(x.max()), float(x[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parents[1],
                        help="the checkout whose code runs (default: this one)")
    tree = parser.parse_args().tree.resolve()
    sys.path[:0] = [str(tree), str(tree / "tools")]
    for send_hz, source_hz in SENDERS:
        lag, error = follow(send_hz, source_hz)
        kind = "every sample its own" if send_hz == source_hz else f"a {source_hz} Hz source resent"
        print(f"sine sent at {send_hz} Hz, {kind}: lag {lag * 1e3:.0f} ms, RMS error {error:.2f} mm")
    for send_hz in (500, 100, 60):
        farthest, rest = stop(send_hz)
        print(f"ramp stopping at 200 mm, sent at {send_hz} Hz: went to {farthest:.1f} mm, at rest at {rest:.3f} mm")


if __name__ == "__main__":
    main()
