"""``hexactl wave``: the wave generator of a running service (docs/api.md, "Wave generator").

Exit 0 when the service took (or, with ``--validate``, would take) the wave, 1 when it
refused it or, with ``--wait``, when the wave did not finish (stopped, aborted, a fault),
2 when nobody answered or the arguments are bad.
"""

from __future__ import annotations

import argparse
import json
import sys
from math import isfinite
from typing import Any

from hexactl.adapters.cli.common import CliError, connect, not_plainly_written, positive_float, positive_up_to, whole_number_in
from hexactl.adapters.cli.service_commands import (
    EXIT_NO_ANSWER,
    EXIT_OK,
    EXIT_REFUSED,
    FRAMES,
    client_parser,
    format_error_reply,
    newest_event_t,
    wait_until_at_rest,
)
from hexactl.control.bounds import MAX_CYCLES, MAX_FREQUENCY_HZ, MAX_PHASE_DEG, amplitude_problem, ramp_problem
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    description = ("play a periodic motion on axes of a frame, ramped in and out, its whole path validated first: "
                   "a wave too fast is refused, never slowed down; hexactl stop or abort brake it to rest")
    wave = subparsers.add_parser("wave", parents=[client_parser()], help="play a sine wave on one or more axes",
                                 description=description)
    wave.add_argument("--axis", action="append", required=True, type=axis_argument, metavar="AXIS:AMPLITUDE[:PHASE]",
                      help="an oscillating axis (x, y, z in mm; roll, pitch, yaw in deg) with its amplitude and phase "
                      "(deg, default 0), e.g. z:2 or roll:0.5:90; repeat for more axes")
    wave.add_argument("--frequency", type=positive_up_to(MAX_FREQUENCY_HZ, "Hz"), required=True, metavar="HZ",
                      help=f"periods per second (at most {MAX_FREQUENCY_HZ:g})")
    wave.add_argument("--cycles", type=whole_number_in(1, MAX_CYCLES), required=True, metavar="N",
                      help="periods, the ramps included")
    wave.add_argument("--ramp", type=positive_float, metavar="CYCLES", help="periods to ramp in, and again to ramp "
                      "out (default 1, or 0.5 for --cycles 1; at most half of --cycles)")
    wave.add_argument("--frame", choices=FRAMES, default="zero", help="zero: the axes of the pose relative to the zero "
                      "posture (default); work: of the tool's pose in the work frame; tool: the tool's own axes, "
                      "turning about the pivot point")
    mode = wave.add_mutually_exclusive_group()
    mode.add_argument("--validate", action="store_true", help="only say whether the service would take it, and its "
                      "figures; nothing moves")
    mode.add_argument("--wait", action="store_true", help="then wait until it is over (exit 1, saying why, unless it "
                      "finished: stopped, aborted, a fault or an E-stop)")
    wave.epilog = ("The reply gives the duration, the legs' peak speed and acceleration and the peak velocity per "
                   "axis. Example: hexactl wave --axis z:2 --axis roll:0.3:90 --frequency 1 --cycles 5 --wait")
    wave.set_defaults(run=run_wave)


def axis_argument(text: str) -> tuple[str, dict[str, float]]:
    """An argparse ``type``: ``AXIS:AMPLITUDE[:PHASE]`` → (axis, its wave fields)."""
    parts = text.split(":")
    if len(parts) not in (2, 3) or parts[0] not in POSE_AXES:
        raise argparse.ArgumentTypeError(f"{text!r}: give AXIS:AMPLITUDE[:PHASE] with AXIS one of "
                                         f"{', '.join(POSE_AXES)}, e.g. z:2 or roll:0.5:90")
    try:
        values = [float(part) for part in parts[1:]]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: the amplitude and the phase are numbers") from None
    if not all(isfinite(value) for value in values):
        raise argparse.ArgumentTypeError(f"{text!r}: the amplitude and the phase are finite numbers")
    if problem := next(filter(None, map(not_plainly_written, parts[1:], values)), None):
        raise argparse.ArgumentTypeError(f"{text!r}: {problem}")
    if problem := amplitude_problem(parts[0], values[0]):
        raise argparse.ArgumentTypeError(f"{text!r}: {problem}")
    if len(values) == 2 and not abs(values[1]) <= MAX_PHASE_DEG:
        raise argparse.ArgumentTypeError(f"{text!r}: the phase is at most ±{MAX_PHASE_DEG:g} deg")
    fields = {"amplitude": values[0], **({"phase_deg": values[1]} if len(values) == 2 else {})}
    return parts[0], fields


def wave_fields(arguments: argparse.Namespace) -> dict[str, Any]:
    """The request's fields from the arguments."""
    axes: dict[str, dict[str, float]] = {}
    for name, fields in arguments.axis:
        if name in axes:
            raise CliError(f"--axis {name} is given twice: one --axis per axis")
        axes[name] = fields
    if arguments.ramp is not None and (problem := ramp_problem(arguments.ramp, arguments.cycles)):
        raise CliError(f"--ramp {problem}")
    ramp = {"ramp_cycles": arguments.ramp} if arguments.ramp is not None else {}
    frame = {"frame": arguments.frame} if arguments.frame != "zero" else {}
    return {"axes": axes, "frequency_hz": arguments.frequency, "cycles": arguments.cycles, **ramp, **frame}


def figures_text(figures: dict[str, Any]) -> str:
    """A wave's figures (the reply's) for people."""
    velocity = ", ".join(f"{axis} {value:.3g} {unit}/s" for axis, unit, value
                         in zip(POSE_AXES, POSE_UNITS, figures["peak_pose_velocity"]) if value)
    return (f"{figures['duration']:.2f} s; peak leg speed {figures['peak_leg_speed_mm_s']:.1f} mm/s (leg "
            f"{figures['peak_leg_speed_leg']}), peak leg acceleration {figures['peak_leg_acceleration_mm_s2']:.0f} "
            f"mm/s² (leg {figures['peak_leg_acceleration_leg']}); peak velocity {velocity or 'none'}")


def run_wave(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import (  # zmq: not for --help
        HexactlClient,
        ServiceUnavailable,
    )

    fields = wave_fields(arguments)
    command = "validate_wave" if arguments.validate else "wave"
    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    try:
        with client:
            since = newest_event_t(client) if arguments.wait else None
            reply = client.request(command, **fields)
            refusal = reply.get("error") if not reply.get("ok") else reply.get("refusal")
            if arguments.json:
                print(json.dumps(reply))
            elif refusal:
                print(format_error_reply({"error": refusal}), file=sys.stderr)
            else:
                print(f"ok: {reply.get('message') or 'valid'}; {figures_text(reply.get('wave') or reply)}", flush=True)
            if refusal:
                return EXIT_REFUSED
            if not arguments.wait:
                return EXIT_OK
            return wait_until_at_rest(client, "wave", reply, since)
    except ServiceUnavailable as error:
        print(f"hexactl wave: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER
