"""``hexactl cue FILE``: replay a vehicle's recorded motion into a running service as motion cues.

The washout filter (:mod:`hexactl.cueing`) turns the vehicle's specific force and angular
rate into platform poses, on the service's active (calibrated) geometry with the
workspace-aware gain, and the poses go to the service as a pose stream
(docs/stream.md) in real time. Exit 0 when the whole file was streamed, 1 when the
service refused the stream or ended it early (a fault, an E-stop, a stop), 2 when
nobody answered or the arguments or files are bad.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from hexactl.adapters.api.protocol import GOAL_TOLERANCE
from hexactl.adapters.cli.common import CliError, connect
from hexactl.adapters.cli.service_commands import (
    EXIT_NO_ANSWER,
    EXIT_OK,
    EXIT_REFUSED,
    client_parser,
    format_error_reply,
    newest_event_t,
    wait_until_at_rest,
)
from hexactl.adapters.cli.telemetry_text import pose_text

if TYPE_CHECKING:  # loaded by the command only
    from hexactl.adapters.api.client import HexactlClient
    from hexactl.cueing.parameters import CueingParameters
    from hexactl.cueing.washout import VehicleTrajectory

CUE_SOURCE = "hexactl cue"

CUE_TIMEOUT_MS = 1000.0
"""The stream's timeout: generous, because a replay's sender is this process (a gap means
a busy host, not a lost simulator), and the platform comes to rest on its last target
anyway when targets stop; the timeout only ends the stream."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    cue = subparsers.add_parser(
        "cue", parents=[client_parser()], help="replay a vehicle's motion into a running service as motion cues",
        description="turn a vehicle trajectory (specific force and angular rate, docs/cueing.md) into platform "
        "poses with the washout filter, on the service's active geometry, and stream them to it in real time "
        "(docs/stream.md); the platform must be enabled and at rest, and is moved to the cue's start pose first")
    cue.add_argument("file", type=Path, help="the vehicle trajectory, CSV: t_s,f_x,f_y,f_z,omega_x,omega_y,omega_z, "
                     "or a shipped one by name: braking, lane_change")
    cue.add_argument("--parameters", type=Path, metavar="TOML", help="the washout's parameters (default: "
                     "config/cueing.toml's values)")
    cue.add_argument("--no-workspace-gain", action="store_true", help="leave the cues at their gains, with only the "
                     "limiter between them and the workspace")
    cue.add_argument("--plan-only", action="store_true", help="only print the plan's figures; nothing moves")
    cue.set_defaults(run=run_cue)


def run_cue(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import CommandError, HexactlClient, ServiceUnavailable
    from hexactl.adapters.files.cueing_file import CueingFileError, load_cueing_parameters, load_vehicle_trajectory
    from hexactl.control.stream_commands import MAX_SAMPLE_GAP_S
    from hexactl.cueing.parameters import CueingParameters

    try:
        vehicle = load_vehicle_trajectory(arguments.file)
        parameters = load_cueing_parameters(arguments.parameters) if arguments.parameters else CueingParameters()
    except CueingFileError as error:
        raise CliError(str(error)) from None
    if vehicle.period_s > MAX_SAMPLE_GAP_S:  # each pose would be a stop: the stream has no velocity between them
        raise CliError(f"{arguments.file}: sample period {vehicle.period_s:g} s: hexactl cue streams one pose per "
                       f"sample, and a stream is followed smoothly only at {1 / MAX_SAMPLE_GAP_S:g} Hz or more "
                       f"({MAX_SAMPLE_GAP_S:g} s apart at most): resample the trajectory (is t_s in seconds?)")
    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    assert isinstance(client, HexactlClient)
    try:
        return _cue(client, vehicle, parameters, arguments)
    except ServiceUnavailable as error:
        print(f"hexactl cue: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER
    except CommandError as error:  # printed as every command prints a refusal
        print(format_error_reply({"error": {"code": error.code, "message": error.message, "details": error.details}}),
              file=sys.stderr)
        return EXIT_REFUSED


def _cue(client: HexactlClient, vehicle: VehicleTrajectory, parameters: CueingParameters,
         arguments: argparse.Namespace) -> int:
    """Plan the cues on the service's geometry and stream them; the exit status."""
    from hexactl.adapters.api.stream_client import PoseStream
    from hexactl.application.cueing import plan_cue
    from hexactl.cueing.workspace_gain import WorkspaceError
    from hexactl.kinematics.geometry import Geometry

    with client:
        geometry = Geometry.model_validate(client.call("geometry")["geometry"])
        try:
            plan = plan_cue(vehicle, parameters, geometry, workspace_gain=not arguments.no_workspace_gain)
        except WorkspaceError as error:
            raise CliError(f"{arguments.file}: {error}") from None
        print(f"{arguments.file}: {len(plan.poses)} poses at {1 / plan.period_s:g} Hz "
              f"({len(plan.poses) * plan.period_s:.1f} s), workspace gain {plan.gain:.2f}, "
              f"specific force RMS error {plan.rms_error:.3f} m/s² (planned)")
        if arguments.plan_only:
            return EXIT_OK
        if (moved := _to_start(client, list(plan.poses[0]))) != EXIT_OK:
            return moved
        with PoseStream(client, CUE_SOURCE, timeout_ms=CUE_TIMEOUT_MS) as stream:
            dropped = stream.send_paced(plan.poses, plan.period_s)
            record = client.call("status")["status"]
        received = record.get("stream_input") or {}
        ended = record.get("last_stream") if record.get("stream") is None else None
        print(f"streamed {len(plan.poses) - dropped} poses ({dropped} dropped here); the service forwarded "
              f"{received.get('forwarded', 0)} to the loop (dropped {received.get('loop_behind', 0)} on the way, the "
              f"loop behind), replaced {received.get('clamped', 0)} out of reach")
        if ended is not None:
            print(f"the stream ended early: {ended['reason']}")
            return EXIT_REFUSED
    return EXIT_OK


def _to_start(client: HexactlClient, start: list[float]) -> int:
    """Move to the cue's first pose (mm, deg) unless the platform is on it, and wait there.
    A stream would take it there at the stream's limits: a cue of its own for whoever is
    aboard; a move goes at its planned pace, validated as every move is."""
    at = client.call("status")["status"]["pose_command"]
    if max(abs(a - b) for a, b in zip(at, start)) <= GOAL_TOLERANCE:
        return EXIT_OK
    print(f"moving to the cue's start pose first: {pose_text(start)}", flush=True)
    since = newest_event_t(client)
    return wait_until_at_rest(client, "move", client.call("move", pose=start), since)
