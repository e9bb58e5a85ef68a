"""``hexactl cue FILE``: replay a vehicle's recorded motion into a running service as motion cues.

The washout filter (:mod:`hexactl.cueing`) turns the vehicle's specific force and angular
rate into platform poses, on the service's active (calibrated) geometry with the
workspace-aware gain, and the poses go to the service as a pose stream
(docs/stream.md) in real time. While it streams, a thread asks the service how the
stream fares, so that a stop, an E-stop, a fault or another client's close ends the
sending at once. Exit 0 when the whole file was streamed, 1 when the service refused the
stream or ended it early, 2 when nobody answered or the arguments or files are bad.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Self

from hexactl.adapters.api.protocol import GOAL_TOLERANCE
from hexactl.adapters.cli.common import CliError, connect, named_path
from hexactl.adapters.cli.service_commands import (
    EXIT_NO_ANSWER,
    EXIT_OK,
    EXIT_REFUSED,
    client_parser,
    format_error_reply,
    newest_event_t,
    wait_until_at_rest,
)
from hexactl.adapters.cli.telemetry_text import event_text, pose_text

if TYPE_CHECKING:  # loaded by the command only
    from hexactl.adapters.api.client import HexactlClient
    from hexactl.adapters.api.stream_client import PoseStream
    from hexactl.application.cueing import CuePlan
    from hexactl.cueing.parameters import CueingParameters
    from hexactl.cueing.washout import VehicleTrajectory

CUE_SOURCE = "hexactl cue"

CUE_TIMEOUT_MS = 1000.0
"""The stream's timeout: generous, because a replay's sender is this process (a gap means
a busy host, not a lost simulator), and the platform comes to rest on its last target
anyway when targets stop; the timeout only ends the stream."""

WATCH_PERIOD_S = 0.05
"""How often the cue asks the service (``status``) whether its stream still follows, while
it streams, s: a stop, an E-stop, a fault or another client's ``stream_close`` ends the
sending within this and a reply's time, 5 samples at 100 Hz, for a request that costs
the service about a millisecond."""

END_WAIT_S = 3.0
"""How long the cue waits, once its stream stopped following, for the service to end it
(it brakes to rest first, well within this) and say why, s."""

CLOSED_BY_A_CLIENT = "closed by the client"
"""The service's reason (docs/api.md, ``last_stream``) for a stream that a ``stream_close``
ended: while the cue streams it is another client's, as the cue closes its own only after
its last pose."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    cue = subparsers.add_parser(
        "cue", parents=[client_parser()], help="replay a vehicle's motion into a running service as motion cues",
        description="turn a vehicle trajectory (specific force and angular rate, docs/cueing.md) into platform "
        "poses with the washout filter, on the service's active geometry, and stream them to it in real time "
        "(docs/stream.md); the platform must be enabled and at rest, and is moved to the cue's start pose first. "
        "--json: the plan's figures, and once streamed the stream's counts and how it ended, as one JSON object")
    cue.add_argument("file", type=named_path, help="the vehicle trajectory, CSV: t_s,f_x,f_y,f_z,omega_x,omega_y,omega_z, "
                     "or a shipped one by name: braking, lane_change")
    cue.add_argument("--parameters", type=named_path, metavar="TOML", help="the washout's parameters (default: "
                     "config/cueing.toml's values)")
    cue.add_argument("--no-workspace-gain", action="store_true", help="leave the cues at their gains, with only the "
                     "limiter between them and the workspace")
    cue.add_argument("--plan-only", action="store_true", help="only print the plan's figures; nothing moves")
    cue.set_defaults(run=run_cue)


def run_cue(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import CommandError, HexactlClient, ServiceUnavailable
    from hexactl.adapters.files.cueing_file import (CueingFileError, angular_rate_note, load_cueing_parameters,
                                                    load_vehicle_trajectory)
    from hexactl.control.stream_commands import MAX_SAMPLE_GAP_S
    from hexactl.cueing.parameters import CueingParameters

    try:
        vehicle = load_vehicle_trajectory(arguments.file)
        parameters = load_cueing_parameters(arguments.parameters) if arguments.parameters else CueingParameters()
    except CueingFileError as error:
        raise CliError(str(error)) from None
    if note := angular_rate_note(vehicle, str(arguments.file)):
        print(f"hexactl cue: note: {note}", file=sys.stderr)
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
        reply = {"error": {"code": error.code, "message": error.message, "details": error.details}}
        print(format_error_reply(reply), file=sys.stderr)
        _print_json(arguments, {"file": str(arguments.file), **reply})
        return EXIT_REFUSED


def _cue(client: HexactlClient, vehicle: VehicleTrajectory, parameters: CueingParameters,
         arguments: argparse.Namespace) -> int:
    """Plan the cues on the service's geometry and stream them; the exit status."""
    from hexactl.application.cueing import plan_cue
    from hexactl.control.preconditions import check_enabled
    from hexactl.control.snapshot import ControlState
    from hexactl.cueing.workspace_gain import WorkspaceError
    from hexactl.kinematics.geometry import Geometry

    with client:
        # Before seconds of planning: the service would refuse the move to the start anyway.
        if not arguments.plan_only and (refusal := check_enabled(ControlState(client.call("status")["status"]["state"]))):
            print(f"hexactl cue: {refusal[1]}; nothing was planned or moved", file=sys.stderr)
            _print_json(arguments, {"file": str(arguments.file), "error": {"code": refusal[0].value,
                                                                           "message": refusal[1], "details": {}}})
            return EXIT_REFUSED
        geometry = Geometry.model_validate(client.call("geometry")["geometry"])
        try:
            plan = plan_cue(vehicle, parameters, geometry, workspace_gain=not arguments.no_workspace_gain)
        except WorkspaceError as error:
            raise CliError(f"{arguments.file}: {error}") from None
        figures = _plan_figures(plan)
        if not arguments.json:
            print(f"{arguments.file}: {figures['poses']} poses at {figures['rate_hz']:g} Hz "
                  f"({figures['duration_s']:.1f} s), workspace gain {plan.gain:.2f}, "
                  f"specific force RMS error {plan.rms_error:.3f} m/s² (planned)")
        if arguments.plan_only:
            _print_json(arguments, {"file": str(arguments.file), "plan": figures})
            return EXIT_OK
        if (moved := _to_start(client, list(plan.poses[0]), arguments.json)) != EXIT_OK:
            return moved
        streamed, ended = _stream(client, plan, arguments)
        _print_json(arguments, {"file": str(arguments.file), "plan": figures, "streamed": streamed, "ended": ended})
        return EXIT_OK if ended is None else EXIT_REFUSED


def _plan_figures(plan: CuePlan) -> dict[str, Any]:
    """What ``hexactl cue`` says of ``plan``: poses, rate (Hz), period and duration (s),
    workspace gain, specific force RMS error (m/s²)."""
    return {"poses": len(plan.poses), "rate_hz": 1 / plan.period_s, "period_s": plan.period_s,
            "duration_s": len(plan.poses) * plan.period_s, "workspace_gain": plan.gain,
            "rms_error_m_s2": plan.rms_error}


def _print_json(arguments: argparse.Namespace, document: dict[str, Any]) -> None:
    """With ``--json``, ``document`` as one line of JSON on stdout (and nothing else there):
    a refusal's too (``error``: ``code``, ``message``, ``details``, as in the API's reply)."""
    if arguments.json:
        print(json.dumps(document))


def _stream(client: HexactlClient, plan: CuePlan, arguments: argparse.Namespace
            ) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """Stream the plan's poses in real time, watched; what was streamed (``sent``,
    ``dropped`` here, and the service's ``forwarded``, ``loop_behind`` and ``clamped``), and
    how the stream ended early (None: it did not), both printed unless ``--json``."""
    from hexactl.adapters.api.client import HexactlClient
    from hexactl.adapters.api.stream_client import PoseStream

    since = _newest_event_seq(client)
    with PoseStream(client, CUE_SOURCE, timeout_ms=CUE_TIMEOUT_MS) as stream:
        assert stream.opened is not None
        number = stream.opened["stream"]
        # A client serves one thread: the watch has a connection of its own.
        watcher = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
        with _StreamWatch(watcher, number) as watch:
            sent, dropped = _send_until_ended(stream, plan.poses, plan.period_s, watch.ended)
        # Asked again after the last pose too: the stream may end between the watch's questions.
        ended = None if _following(client.call("status")["status"], number) else _how_it_ended(client, number, since)
    record = client.call("status")["status"]
    received = record.get("stream_input") or {}
    streamed = {"sent": sent - dropped, "dropped": dropped, "forwarded": received.get("forwarded", 0),
                "loop_behind": received.get("loop_behind", 0), "clamped": received.get("clamped", 0),
                "holding_at": record.get("pose_command")}
    _say_streamed(streamed, ended, len(plan.poses), arguments.json)
    return streamed, ended


def _say_streamed(streamed: dict[str, Any], ended: dict[str, Any] | None, planned: int, quiet: bool) -> None:
    """What was ``streamed`` of the ``planned`` poses, on stdout unless ``quiet`` (``--json``),
    and how the stream ended early (``ended``; None: it did not), on stderr."""
    if not quiet:
        print(f"streamed {streamed['sent']} of {planned} poses ({streamed['dropped']} dropped here); the service "
              f"forwarded {streamed['forwarded']} to the loop (dropped {streamed['loop_behind']} on the way, the loop "
              f"behind), replaced {streamed['clamped']} out of reach")
        if (pose := streamed["holding_at"]) and any(abs(value) > GOAL_TOLERANCE for value in pose):
            # The washout had not brought it back when the cues ended (docs/cueing.md): it stays there.
            print(f"the platform holds where the cue left it, {pose_text(pose)}: hexactl move 0,0,0,0,0,0 takes it "
                  "back to the zero posture")
    if ended is not None:
        sent = streamed["sent"] + streamed["dropped"]
        print(f"hexactl cue: the stream ended after {sent} of {planned} poses: {ended['reason']}"
              + (f"\n  the service recorded since it opened: {'; '.join(ended['events'])}" if ended["events"] else ""),
              file=sys.stderr, flush=True)


def _send_until_ended(stream: PoseStream, poses: Sequence[Sequence[float]], period_s: float,
                     ended: threading.Event) -> tuple[int, int]:
    """Send ``poses`` (mm, deg) one every ``period_s`` (s) in real time, from absolute
    deadlines (a late one does not delay the rest), until the last or until ``ended`` is
    set: waiting for the next deadline is waiting for ``ended``, so the sending stops the
    moment it is. The poses sent and, of them, dropped (the socket could not take them)."""
    start = time.monotonic()
    dropped = stream.dropped
    for sent, pose in enumerate(poses):
        if ended.wait(max(0.0, start + sent * period_s - time.monotonic())):
            return sent, stream.dropped - dropped
        stream.send(pose)
    return len(poses), stream.dropped - dropped


class _StreamWatch:
    """Asks the service through ``client`` (a connection of its own: one thread's) every
    :data:`WATCH_PERIOD_S` whether stream ``stream`` still follows, in a thread, so that
    the sending never waits for a reply. ``ended`` is set once it does not (braking to
    rest, ended, or the controller out of ``enabled``). A request that goes unanswered is
    asked again: a busy service, or one gone, which the cue's own requests then report.
    Used in a ``with`` statement, which starts the watch and stops it and the client."""

    def __init__(self, client: HexactlClient, stream: int) -> None:
        self._client = client
        self._stream = stream
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="hexactl cue watch", daemon=True)
        self.ended = threading.Event()

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(self, *exception: object) -> None:
        self._stop.set()
        self._thread.join()
        self._client.close()

    def _watch(self) -> None:
        from hexactl.adapters.api.client import CommandError, ServiceUnavailable

        while not self._stop.wait(WATCH_PERIOD_S):
            try:
                record = self._client.call("status")["status"]
            except (ServiceUnavailable, CommandError):
                continue
            if not _following(record, self._stream):
                self.ended.set()
                return


def _following(record: dict[str, Any], stream: int) -> bool:
    """Whether the status ``record`` shows stream ``stream`` following its targets."""
    current = record.get("stream")
    return (record["state"] == "enabled" and current is not None and current["stream"] == stream
            and current["phase"] == "following")


def _newest_event_seq(client: HexactlClient) -> int:
    """The number of the loop's newest event (0: none yet)."""
    return int(client.call("events", after=0)["last"])


def _how_it_ended(client: HexactlClient, stream: int, since: int) -> dict[str, Any]:
    """How stream ``stream``, no longer following, ended: ``reason`` (the service's, once it
    has braked to rest, waited for up to :data:`END_WAIT_S`; a close said to be another
    client's) and ``events``, what the loop recorded after event ``since``, as text."""
    deadline = time.monotonic() + END_WAIT_S
    record = client.call("status")["status"]
    while (record.get("stream") or {}).get("stream") == stream and time.monotonic() < deadline:
        time.sleep(WATCH_PERIOD_S)
        record = client.call("status")["status"]
    last = record.get("last_stream") or {}
    if last.get("stream") != stream:
        reason = f"it is still braking to rest after {END_WAIT_S:g} s (the controller is {record['state']})"
    elif last["reason"] == CLOSED_BY_A_CLIENT:
        reason = "another client closed it (stream_close), not this cue"
    else:
        reason = last["reason"]
    recorded = client.call("events", after=since)
    return {"reason": reason, "events": [event_text(event, recorded["t"]) for event in recorded["events"]
                                         if event["code"] != "stream_opened"]}


def _to_start(client: HexactlClient, start: list[float], quiet: bool) -> int:
    """Move to the cue's first pose (mm, deg) unless the platform is on it, and wait there
    (saying so on stdout, on stderr when ``quiet``: ``--json``'s stdout is its JSON).
    A stream would take it there at the stream's limits: a cue of its own for whoever is
    aboard; a move goes at its planned pace, validated as every move is."""
    at = client.call("status")["status"]["pose_command"]
    if max(abs(a - b) for a, b in zip(at, start)) <= GOAL_TOLERANCE:
        return EXIT_OK
    since = newest_event_t(client)
    reply = client.call("move", pose=start)  # a refusal raises, before anything is said of moving
    print(f"moving to the cue's start pose first: {pose_text(start)}", file=sys.stderr if quiet else sys.stdout,
          flush=True)
    return wait_until_at_rest(client, "move", reply, since)
