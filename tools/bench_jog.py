"""How long the facade takes to answer a jog: the first request (finding the limit ahead
and planning the move to it), a renewal (no planning), and a re-plan (another velocity
while jogging). This is the operator's latency from pressing a key to the command going
to the loop, besides the API's transport; the loop itself adds at most a cycle.

The controller runs on ideal in-memory actuators in simulated time (the control tests'
rig); ``time.perf_counter`` around ``Controller.jog`` only. Each figure is over
``--repeats`` jogs in directions spread over the six axes, with and without soft limits.

    python3 tools/bench_jog.py --repeats 20
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.control.config import ControllerConfig  # noqa: E402
from hexactl.control.frames import Frame, OperatorFrames  # noqa: E402
from hexactl.control.local_controller import LocalController  # noqa: E402
from hexactl.kinematics.inverse import sensor_setpoints  # noqa: E402
from hexactl.kinematics.soft_limits import SoftLimits  # noqa: E402
from hexactl.sim.ideal_actuators import IdealActuators  # noqa: E402

VELOCITIES = [(20, 0, 0, 0, 0, 0), (0, -20, 0, 0, 0, 0), (0, 0, 10, 0, 0, 0), (0, 0, 0, 1, 0, 0),
              (0, 0, 0, 0, -1, 0), (0, 0, 0, 0, 0, 2), (10, 10, 5, 0, 0, 0), (0, 0, 0, 1, 1, 0)]
SOFT = OperatorFrames(soft_limits=SoftLimits(lower=(-40, -40, -30, -3, -3, -5), upper=(40, 40, 30, 3, 3, 5)))


class _Rig:
    def __init__(self) -> None:
        self.now = 1_000_000_000
        geometry = load_geometry(default_config_path())
        actuators = IdealActuators(sensor_setpoints(geometry.legs, geometry.home.in_radians()), clock_ns=lambda: self.now)
        self.controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(),
                                                    clock_ns=lambda: self.now)
        self.period = self.controller.config.loop.period_ns

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.now += self.period
            self.controller.step(self.now)


def _timed(call) -> float:
    begin = time.perf_counter()
    result = call()
    elapsed = time.perf_counter() - begin
    assert result.ok, result.message
    return elapsed * 1e3


def measure(frames: OperatorFrames | None, repeats: int) -> dict[str, list[float]]:
    rig = _Rig()
    if frames is not None:
        assert rig.controller.set_frames(frames).ok
    assert rig.controller.enable().ok
    rig.run(3)
    times: dict[str, list[float]] = {"start": [], "renewal": [], "re-plan": []}
    for n in range(repeats):
        velocity = VELOCITIES[n % len(VELOCITIES)]
        times["start"].append(_timed(lambda: rig.controller.jog(velocity)))
        rig.run(25)
        times["renewal"].append(_timed(lambda: rig.controller.jog(velocity)))
        rig.run(25)
        turned = VELOCITIES[(n + 3) % len(VELOCITIES)]
        times["re-plan"].append(_timed(lambda: rig.controller.jog(turned, Frame.ZERO)))
        rig.run(25)
        assert rig.controller.jog([0] * 6).ok
        rig.run(1500)
        assert rig.controller.move([0, 0, 0, 0, 0, 0]).ok
        rig.run(2500)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=16)
    arguments = parser.parse_args()
    print(f"{'case':<28}{'median ms':>10}{'p90 ms':>10}{'max ms':>10}")
    for label, frames in (("no soft limits", None), ("soft limits", SOFT)):
        for kind, values in measure(frames, arguments.repeats).items():
            ordered = sorted(values)
            p90 = ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))]
            print(f"{label + ', ' + kind:<28}{statistics.median(values):>10.2f}{p90:>10.2f}{max(values):>10.2f}")


if __name__ == "__main__":
    main()
