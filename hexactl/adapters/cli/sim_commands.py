"""``hexactl sim-actuators``: the six simulated actuators on a CAN bus, in their own process."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from types import FrameType
from typing import TYPE_CHECKING

from hexactl.adapters.cli.common import (LEG_LABELS, CliError, checked_number, fifo_priority, load_config,
                                        non_negative_int, parse_numbers, positive_float)

if TYPE_CHECKING:  # the simulator and python-can load when the command runs, not for every command
    from hexactl.kinematics.geometry import Geometry

SIMULATOR_RECEIVE_BUFFER_BYTES = 8 << 20
"""The simulator's SocketCAN receive buffer: about 10 000 classic frames, over 5 s of a
controller at 500 Hz (four frames a cycle)."""


MAX_TICK_MS = 1000.0
"""A coarser physics tick leaves the actuators silent for longer than any controller's
watchdog; above it, the tick's timestamps overflowed."""


def _tick_problem(tick_ms: float) -> str | None:
    return None if 0 < tick_ms <= MAX_TICK_MS else f"{tick_ms:g} is not a tick from 0 to {MAX_TICK_MS:g} ms"


def _probability_problem(probability: float) -> str | None:
    return None if 0 <= probability <= 1 else f"{probability:g} is not a probability from 0 to 1"


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    sim = subparsers.add_parser(
        "sim-actuators",
        parents=[common],
        help="run the six simulated actuator firmwares on a CAN bus",
        description="Run six simulated actuators (firmware, drive, sensor) speaking the hexapod CAN "
        "protocol on a bus, with the simulated physical platform behind them. Prints one JSON line "
        "when ready and one with the final state when stopped (SIGINT, SIGTERM or --duration).",
        epilog="Stroke and speed limit come from the geometry's [limits]. The actuators start at the "
        "readings that put the true platform in its zero posture unless --positions is given. "
        "See docs/can.md.",
    )
    sim.add_argument("--can", required=True, metavar="SPEC", help="bus: socketcan:CHANNEL (e.g. socketcan:vcan0)")
    sim.add_argument("--seed", type=non_negative_int, default=0, help="seed of the true platform's manufacturing errors and "
                     "of injected frame faults (default 0)")  # fmt: skip
    sim.add_argument("--true-geometry", metavar="FILE", help="geometry file of the true platform "
                     "(default: the --config geometry with seeded manufacturing errors)")  # fmt: skip
    sim.add_argument("--positions", metavar="L1,...,L6", help="start readings, mm")
    sim.add_argument("--tick-ms", type=checked_number(_tick_problem), default=1.0,
                     help=f"physics tick, ms (default 1, at most {MAX_TICK_MS:g})")
    sim.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds")
    sim.add_argument("--drop-probability", type=checked_number(_probability_problem), default=0.0,
                     help="each received frame is lost with this probability")
    sim.add_argument("--corrupt-probability", type=checked_number(_probability_problem), default=0.0,
                     help="each received frame is corrupted (bad CRC) with this probability")  # fmt: skip
    sim.add_argument("--fifo", type=fifo_priority(1), metavar="PRIO",
                     help="SCHED_FIFO priority 1-99 of the simulator, set once it is ready (its start-up would "
                     "hold up the rest of a busy host); the ready line says what it got (default: normal "
                     "scheduling)")  # fmt: skip
    sim.set_defaults(run=run_sim_actuators)


def _true_geometry(arguments: argparse.Namespace, nominal: Geometry) -> Geometry:
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.kinematics.geometry import GeometryError
    from hexactl.sim.true_platform import true_geometry

    try:
        if arguments.true_geometry:
            return load_geometry(arguments.true_geometry)
        return true_geometry(nominal, arguments.seed)
    except GeometryError as error:
        raise CliError(str(error)) from None


def run_sim_actuators(arguments: argparse.Namespace) -> int:
    import can

    from hexactl.adapters.can.transport import BusSpecError, in_process_note, open_bus, parse_bus_spec
    from hexactl.sim.actuator_bus import ActuatorBus, actuator_params_for, make_firmwares, zero_posture_readings_mm
    from hexactl.sim.physical_platform import PhysicalPlatform, PoseUnavailable

    nominal = load_config(arguments)
    truth = _true_geometry(arguments, nominal)
    if arguments.positions:
        positions = parse_numbers(arguments.positions.split(","), LEG_LABELS)
    else:
        positions = zero_posture_readings_mm(truth)
    try:
        spec = parse_bus_spec(arguments.can)
        if note := in_process_note(spec):
            print(f"hexactl sim-actuators: --can {note}", file=sys.stderr)
        firmwares = make_firmwares(positions, actuator_params_for(nominal), seed=arguments.seed)
    except (BusSpecError, ValueError) as error:
        raise CliError(str(error)) from None
    for firmware in firmwares:
        firmware.inject.drop_probability = arguments.drop_probability
        firmware.inject.corrupt_probability = arguments.corrupt_probability
    try:
        # On SocketCAN, room for seconds of the controller's frames: a simulator held up by
        # a loaded host reads them late, at their arrival times, instead of losing them (real
        # actuators have a processor each).
        options = {"receive_buffer_bytes": SIMULATOR_RECEIVE_BUFFER_BYTES} if spec.interface == "socketcan" else {}
        bus = open_bus(spec, **options)
    except (can.CanError, OSError) as error:
        raise CliError(f"cannot open {spec}: {error}") from None

    runner = ActuatorBus(bus, firmwares, tick_s=arguments.tick_ms / 1000.0)
    platform = PhysicalPlatform(truth, runner.actual_positions_mm)

    def stop(signum: int, frame: FrameType | None) -> None:
        runner.stop()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    _print_json({"ready": True, "can": str(spec), "positions_mm": positions, "true_geometry": truth.name,
                 "scheduling": _scheduling(arguments.fifo)})
    try:
        runner.serve(arguments.duration)
    finally:
        bus.shutdown()
    try:
        pose = list(platform.true_pose().relative)
    except PoseUnavailable:
        pose = None
    _print_json(
        {
            "stopped": True,
            "positions_mm": list(runner.actual_positions_mm()),
            "states": [firmware.state.name for firmware in firmwares],
            "faults": [int(firmware.faults) for firmware in firmwares],
            "rejected_frames": [firmware.rejected_total for firmware in firmwares],
            "frames_sent": runner.frames_sent,
            "send_failures": runner.send_failures,
            "true_pose_relative": pose,
        }
    )
    return 0


def _scheduling(priority: int | None) -> str:
    """Put this process's one thread under SCHED_FIFO at ``priority`` (None: leave it);
    what it runs under, or why not, in words."""
    from hexactl.control.realtime import set_fifo

    if priority is None:
        return "normal scheduling"
    return set_fifo(priority) or f"SCHED_FIFO {priority}"


def _print_json(document: dict[str, object]) -> None:
    print(json.dumps(document), flush=True)
    sys.stdout.flush()
