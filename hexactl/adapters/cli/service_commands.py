"""``hexactl serve``, the clients of a running service (``status``, ``enable``, ``move``, …)
and ``hexactl keys``; ``hexactl monitor`` is :mod:`hexactl.adapters.cli.monitor`.

Client commands print the reply (human-readable, or the raw JSON with ``--json``) and
exit 0 when the service carried the command out, 1 when it refused it (an error
reply), 2 when nobody answered within ``--timeout`` or the arguments are bad.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hexactl.adapters.api.protocol import (
    DEFAULT_API_ENDPOINT,
    DEFAULT_TELEMETRY_ENDPOINT,
    DEFAULT_TELEMETRY_RATE_HZ,
    GOAL_TOLERANCE,
)
from hexactl.adapters.cli.common import (
    CliError,
    MergedBounds,
    NO_BOUND,
    bind_endpoint,
    bound_changes_argument,
    check_writable,
    client_endpoint,
    connect,
    connection_parser,
    fifo_priority,
    fraction,
    named_path,
    pose_argument,
    positive_float,
    positive_up_to,
    telemetry_rate,
    tilt_bound_argument,
    whole_number,
    write_failed,
)
from hexactl.adapters.cli.dashboard_commands import DEFAULT_HTTP, checked_http
from hexactl.adapters.cli.telemetry_text import event_text, format_telemetry, frames_lines, pose_text
from hexactl.control.bounds import MAX_MOTION_S
from hexactl.control.results import wave_ended_message
from hexactl.kinematics.axes import MAX_TILT_DEG

EXIT_OK, EXIT_REFUSED, EXIT_NO_ANSWER = 0, 1, 2
FRAMES = ("zero", "work", "tool")
"""``move --frame``'s choices: the API's frames (docs/api.md)."""

RequestBuilder = Callable[[argparse.Namespace], tuple[str, dict[str, Any]]]
"""Arguments → (command, request fields)."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    _register_serve(subparsers, common)
    client = client_parser()

    def command(name: str, help_text: str, build: RequestBuilder | str) -> argparse.ArgumentParser:
        """A client sub-command sending what ``build`` makes of the arguments (a bare
        command name: no fields)."""
        make = (lambda arguments: (build, {})) if isinstance(build, str) else build
        parser = subparsers.add_parser(name, parents=[client], help=help_text, description=help_text)
        parser.set_defaults(run=lambda arguments: run_client_command(arguments, *make(arguments)))
        return parser

    command("status", "the running service's state (one telemetry record)", "status")
    command("enable", "energise the actuators; the platform holds its pose", "enable")
    command("disable", "de-energise the actuators (at rest only: stop first)", "disable")
    move = command("move", "move to a pose (relative to the zero posture, or in the work frame), or by one",
                   _move_request)
    move.add_argument("pose", metavar="POSE", type=pose_argument, help="X,Y,Z,ROLL,PITCH,YAW (mm, deg) or axis=value pairs, e.g. z=50,yaw=5")
    pace = move.add_mutually_exclusive_group()
    pace.add_argument("--duration", type=positive_up_to(MAX_MOTION_S, "s"), metavar="S",
                      help=f"minimum duration of the move, s (at most {MAX_MOTION_S:g})")
    pace.add_argument("--speed", type=fraction, metavar="F", help="fraction (0, 1] of the velocity limits")
    move.add_argument("--frame", choices=FRAMES, default="zero",
                      help="zero: the platform relative to the zero posture (default); work: the tool's pose in the "
                      "work frame, turning about the pivot point; tool: with --relative, along and about the tool's axes")
    move.add_argument("--relative", action="store_true", help="POSE is a displacement from where the motion is headed")
    move.add_argument("--tolerance", type=positive_float, metavar="MM",
                      help="refuse the move if the calibration's predicted 1σ error at the tool point on arrival "
                      "exceeds this, mm")
    _waiting(move)
    move.add_argument("--validate", action="store_true", help="only say whether the service would take the move from "
                      "here, its whole goal (the axes not given included) and its duration; nothing moves")
    move.epilog = ("A pose may start with a minus sign (move -10,0,0,0,0,0). An absolute pose's axes not given are 0: "
                   "--validate shows the whole goal first. In leg-lock mode the goal is projected onto the locked "
                   "leg's constraint: the reply prints the goal run to when it differs. Frames: hexactl frames.")
    frames = command("frames", "show or set the work and tool frames (the pivot point) and the soft limits",
                     _frames_request)
    frames.add_argument("--work", type=pose_argument, metavar="POSE",
                        help="the work frame in the zero frame (mm, deg), whole: axes not given are 0")
    frames.add_argument("--tool", type=pose_argument, metavar="POSE",
                        help="the tool frame in the platform's frame (mm, deg): its origin is the pivot point; whole, "
                        "axes not given are 0")
    frames.add_argument("--soft-lower", type=bound_changes_argument, action=MergedBounds, metavar="BOUNDS",
                        help=f"lower soft bounds on the tool's pose in the work frame, axis=value pairs, e.g. "
                        f"x=-50,z=-10 ({NO_BOUND}: remove that bound); given again, its pairs add up")
    frames.add_argument("--soft-upper", type=bound_changes_argument, action=MergedBounds, metavar="BOUNDS",
                        help="upper soft bounds, likewise")
    frames.add_argument("--max-tilt", type=tilt_bound_argument, metavar="DEG",
                        help=f"soft bound on the tool's tilt, deg (at most {MAX_TILT_DEG:g}; {NO_BOUND}: remove it)")
    frames.add_argument("--clear", action="store_true", help="no frames and no soft limits")
    frames.epilog = ("Without options: show them. Each option changes only what it names: --work and --tool each set "
                     "a whole frame (--work z=305 is 0,0,305,0,0,0: give every axis to keep the others); --soft-lower "
                     f"x=-40 sets x's lower bound and keeps every other soft limit; x={NO_BOUND} removes one. Saved by "
                     "the service, restored on restart.")
    command("stop", "halt any motion smoothly and stay enabled", "stop")
    play = command("play", "play a sequence: a built-in name, a sequence file or a plan", _play_request)
    play.add_argument("sequence", metavar="SEQUENCE", type=named_path, help="built-in name (x_sweep, y_rotation, compound), a .toml "
                      "sequence file or a .csv plan from plan-leglock: a file here is sent by its absolute path, any "
                      "other name is looked up in the service's data directories (serve puts examples in ./sequences)")
    _waiting(play)
    play.add_argument("--validate", action="store_true", help="only say whether the service would take the "
                      "sequence's paths from where the motion under way ends, and its duration; nothing moves (also "
                      "while disabled)")
    play.epilog = ("In leg-lock mode each waypoint is projected onto the locked leg's constraint: the reply says how "
                   "far the farthest one moves (--json: each one's, lock_corrections_mm).")
    command("pause", "pause the playing sequence", "pause")
    _waiting(command("resume", "resume the paused sequence", "resume"))
    command("abort", "abandon the playing sequence (halts smoothly)", "abort")
    leg_lock = command("leg-lock", "lock one leg at its current length (leg-lock calibration mode)", _leg_lock_request)
    leg_lock.add_argument("leg", type=whole_number, choices=range(1, 7), metavar="N", help="leg 1–6")
    command("unlock", "release the locked leg", "leg_unlock")
    load = command("load-calibration", "switch the running service to a calibration file", _load_calibration_request)
    load.add_argument("file", metavar="FILE", type=named_path, help="calibration TOML: a file here is read here and its content sent (so "
                      "any file works, for a local or a remote service); a name that is no file here is read by the "
                      "service from its data directories")
    load.add_argument("--send", action="store_true", help="insist that FILE is read here (the default when it exists here)")
    check = load.add_mutually_exclusive_group()
    check.add_argument("--preview", action="store_true", help="only say whether the service would load it now, its "
                       "calibration id and how far the set-points would change; nothing is loaded")
    check.add_argument("--expected-id", metavar="ID",
                       help="load it only if it is the calibration ID a --preview showed (refused "
                       "changed_since_validation, nothing loaded, if the file was rewritten since)")
    load.epilog = ("Preview, then apply what was previewed: hexactl load-calibration cal.toml --preview, then "
                   "hexactl load-calibration cal.toml --expected-id ID.")
    command("rollback-calibration", "return to the calibration active before the last load", "rollback_calibration")
    save = command("save-recording", "write the last sequence's dwell records as CSV on the service's machine", _save_recording_request)
    save.add_argument("file", metavar="FILE", type=named_path, help="new CSV file (never overwritten): a bare name (run1.csv) goes into the "
                      "service's first data directory; a path with a directory (recordings/run1.csv) names that directory, "
                      "sent absolute when it exists here (a service in the same working directory), else as typed; it "
                      "must be a data directory of the service")
    command("estop", "emergency stop: every actuator stops and holds at once", "estop")
    command("reset", "clear faults and an emergency stop whose cause is gone", "reset")

    keys = subparsers.add_parser(
        "keys", help="make CURVE keys for a service bound beyond localhost",
        description="Make a client key pair (ZeroMQ certificates) in DIR, and the server's unless DIR has it, and allow "
        "the client in DIR/clients. "
        "Serve with --curve-secret DIR/server.key_secret --curve-clients DIR/clients; connect with "
        "--curve-server DIR/server.key --curve-client DIR/NAME.key_secret.",
    )
    keys.add_argument("--out", required=True, type=named_path, metavar="DIR")
    keys.add_argument("--name", default="client", help="the client's name (default client); run again with another name to add a client")
    keys.set_defaults(run=run_keys)


def _register_serve(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    serve = subparsers.add_parser(
        "serve", parents=[common], help="run the controller service (default: the built-in simulator)",
        declare=_declare_serve,
    )
    serve.set_defaults(run=run_serve)


def _declare_serve(serve: argparse.ArgumentParser) -> None:
    # The service's modules: serve loads them to run anyway; no other command does.
    from hexactl.application.service import API_URGENT_NICENESS
    from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY

    serve.description = (
        "Run the control loop with the ZeroMQ API and telemetry. Without --can, six simulated "
        "actuators on an in-process CAN bus drive a simulated platform. Real-time by default: the loop under "
        f"SCHED_FIFO {DEFAULT_FIFO_PRIORITY} and the memory locked, when the process may (root, CAP_SYS_NICE or "
        "RLIMIT_RTPRIO; CAP_IPC_LOCK or an unlimited RLIMIT_MEMLOCK), else normal scheduling with the reason "
        "logged; the log and status say what it got. SIGINT/SIGTERM/SIGHUP brake the platform to rest, disable the "
        "actuators and stop, within 10 s."
    )
    serve.add_argument("--can", metavar="SPEC", help="CAN bus of real actuators, e.g. socketcan:can0 (default: the simulator)")
    serve.add_argument("--calibration", type=named_path, metavar="FILE", help="start with this calibration instead of "
                       "the one kept from the last run (--keep-calibration) or, if none, the --config geometry")
    serve.add_argument("--rate", type=whole_number, choices=(250, 500, 1000), default=500, metavar="HZ",
                       help="control loop rate: 250, 500 (default) or 1000 Hz (the protocol's rates; with --can, "
                            "1000 Hz overloads classic CAN, the only profile the link speaks: docs/can.md)")
    realtime = serve.add_mutually_exclusive_group()
    realtime.add_argument("--fifo", type=fifo_priority(2), default=DEFAULT_FIFO_PRIORITY, metavar="PRIO",
                          help=f"SCHED_FIFO priority 2-99 of the loop (default {DEFAULT_FIFO_PRIORITY}: real-time is the "
                          "default, --no-realtime turns it off); PRIO-1 for the simulator's thread, which shares the "
                          f"loop's GIL; the API process's threads on the way of a stop get nice {API_URGENT_NICENESS}; "
                          "capped at RLIMIT_RTPRIO without CAP_SYS_NICE")
    realtime.add_argument("--no-realtime", action="store_true",
                          help="normal scheduling and no memory locking, even with the privilege")
    serve.add_argument("--mlock", action="store_true",
                       help="accepted for compatibility: the memory is locked by default (--no-realtime: not)")
    serve.add_argument("--api", type=bind_endpoint, default=DEFAULT_API_ENDPOINT, metavar="ENDPOINT", help=f"command endpoint (default {DEFAULT_API_ENDPOINT})")
    serve.add_argument("--telemetry", type=bind_endpoint, default=DEFAULT_TELEMETRY_ENDPOINT, metavar="ENDPOINT", help=f"telemetry endpoint (default {DEFAULT_TELEMETRY_ENDPOINT})")
    serve.add_argument("--telemetry-rate", type=telemetry_rate, default=DEFAULT_TELEMETRY_RATE_HZ, metavar="HZ", help=f"telemetry records per second (default {DEFAULT_TELEMETRY_RATE_HZ:g})")
    serve.add_argument(
        "--data-dir", action="append", type=named_path, metavar="DIR",
        help="directory requests may read calibration and sequence files from and write recordings to "
        "(repeatable; default: ./recordings, ./calibrations, ./sequences and the config file's directory)",
    )
    serve.add_argument("--frames", type=named_path, metavar="FILE", help="where the operator's frames and soft limits are "
                       "kept across restarts (default ./frames.toml; read at start only, written when they change; "
                       "a hand edit under a running service is kept aside as FILE.changed-TIME, not read)")
    serve.add_argument("--keep-calibration", type=named_path, metavar="FILE",
                       help="where the calibration in force is kept across restarts (default ./active_calibration.toml;"
                       " restored at start without --calibration; follows the calibration the loop has in force, even "
                       "after a loop_timeout: written when it changes, removed when the nominal geometry is back; a hand "
                       "edit under a running service is kept aside as FILE.changed-TIME, not read)")
    serve.add_argument("--curve-secret", type=Path, metavar="FILE", help="CURVE server secret key (needed to bind beyond localhost)")
    serve.add_argument("--curve-clients", type=Path, metavar="DIR", help="directory of the client public keys allowed in")
    serve.add_argument("--dashboard", nargs="?", const=DEFAULT_HTTP, metavar="HOST:PORT",
                       help=f"also serve the browser dashboard (hexactl dashboard) there (default {DEFAULT_HTTP}), in "
                       "a process of its own, stopped with the service")
    serve.add_argument("--stream", type=bind_endpoint, metavar="ENDPOINT", help="the pose stream's ZeroMQ socket (default: the API's "
                       "host, a free port; stream_open's reply tells clients where)")
    serve.add_argument("--stream-udp", metavar="HOST:PORT", help="also take the pose stream's samples as UDP "
                       "datagrams there, for motion-simulator software (docs/stream.md). UDP has no authentication: "
                       "beyond loopback, whoever reaches the port steers the platform while a stream is open")
    serve.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def udp_address(text: str) -> tuple[str, int]:
    """``--stream-udp``'s HOST:PORT (an IPv4 address, a port 1–65535, or 0: a free one,
    which ``stream_open``'s reply names); CliError otherwise."""
    import ipaddress

    host, _, port = text.rpartition(":")
    try:
        ipaddress.IPv4Address(host)
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise CliError(f"--stream-udp wants HOST:PORT with an IPv4 address and a port 0-65535 (e.g. 127.0.0.1:5558), "
                       f"got {text!r}")
    return host, number


def _waiting(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--wait", action="store_true", help="then wait until the platform is at rest and the sequence "
                        "over (exit 1, saying why, if a fault, an E-stop or a pause ends or holds it, or a stop leaves it short of "
                        "its goal)")


def client_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(add_help=False, parents=[connection_parser()])
    parser.add_argument("--api", type=client_endpoint, metavar="ENDPOINT", help=f"the service's command endpoint (default $HEXACTL_API, else the "
                        f"client file's api, else {DEFAULT_API_ENDPOINT})")
    parser.add_argument("--json", action="store_true", help="print the raw JSON reply")
    return parser


# -- requests from arguments ---------------------------------------------------------


def _move_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    if arguments.validate and arguments.wait:
        raise CliError("--validate moves nothing, so there is nothing to --wait for: give one of them")
    if arguments.frame == "tool" and not arguments.relative:  # the service would refuse it (exit 1) as bad input
        raise CliError("--frame tool moves relative to where the tool is (it is always at its own origin): add "
                       "--relative")
    pace = {name: getattr(arguments, name) for name in ("duration", "speed") if getattr(arguments, name) is not None}
    frame = {"frame": arguments.frame} if arguments.frame != "zero" else {}
    tolerance = {"tolerance_mm": arguments.tolerance} if arguments.tolerance is not None else {}
    return "validate_pose" if arguments.validate else "move", {
        "pose": arguments.pose, **pace, **frame, **({"relative": True} if arguments.relative else {}), **tolerance}


def _frames_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    fields: dict[str, Any] = {name: value for name, value in (("work", arguments.work), ("tool", arguments.tool))
                              if value is not None}
    changes = {side: bounds for side, bounds in (("lower", arguments.soft_lower), ("upper", arguments.soft_upper))
               if bounds is not None}
    if arguments.max_tilt is not None:
        changes["max_tilt_deg"] = None if arguments.max_tilt == NO_BOUND else arguments.max_tilt
    if arguments.clear:
        if fields or changes:
            raise CliError("--clear takes no other frame option: clear, then set")
        return "clear_frames", {}
    if changes:
        fields["soft_limit_changes"] = changes  # the service changes them against those in force, the others kept
    return ("set_frames", fields) if fields else ("frames", {})


def _leg_lock_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    return "leg_lock", {"leg": arguments.leg}


REQUEST_ENVELOPE_BYTES = 256
"""Room a request's envelope (version, id, command, deadline) takes beside its fields."""


def _play_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    if arguments.validate and arguments.wait:
        raise CliError("--validate plays nothing, so there is nothing to --wait for: give one of them")
    path = Path(arguments.sequence)  # a file here is sent absolute: the service's working directory may differ
    if path.is_dir():
        raise CliError(f"{arguments.sequence}: a directory, not a sequence: name a .toml sequence file or a .csv "
                       "plan in it, or a built-in sequence")
    return "validate_sequence" if arguments.validate else "play", {
        "sequence": str(path.resolve()) if path.is_file() else str(arguments.sequence)}


def _save_recording_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """The rule of ``save-recording FILE``'s help: only a path with a directory part that
    exists here is made absolute; a bare name stays one, for the service to put in its
    first data directory (docs/api.md)."""
    path = Path(arguments.file)
    here = path.parent != Path() and path.parent.is_dir()
    return "save_recording", {"path": str(path.resolve()) if here else str(arguments.file)}


def _load_calibration_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """A file here is read and checked to be TOML here, and sent as content with its
    name; any other name goes to the service, which looks it up in its data directories.
    A file too large for a request (comments, a long history) goes by its absolute path:
    the service reads it if it lies in one of its data directories, and else says which
    they are (it said "too_large", or for 2 MB nothing at all)."""
    cmd = "validate_calibration" if arguments.preview else "load_calibration"
    fields = _load_calibration_fields(arguments)
    return cmd, fields if arguments.expected_id is None else {**fields, "expected_id": arguments.expected_id}


def _load_calibration_fields(arguments: argparse.Namespace) -> dict[str, Any]:
    """The file's ``toml`` (and ``source``), or its ``path`` for the service to read."""
    path = Path(arguments.file)
    if path.is_dir():  # else sent as a name, and the service's "no such file" misleads
        raise CliError(f"{arguments.file}: a directory, not a calibration file: name the .toml file in it "
                       f"(hexactl calibrate writes calibration.toml)")
    if not (arguments.send or path.is_file()):
        return {"path": str(arguments.file)}
    import json
    import tomllib  # light; only for this command

    from hexactl.adapters.api.protocol import MAX_REQUEST_BYTES
    from hexactl.adapters.files.text import read_text

    text = read_text(arguments.file, CliError)

    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise CliError(f"{arguments.file}: not valid TOML: {error}") from None
    fields = {"toml": text, "source": str(path.resolve())}
    if len(json.dumps(fields).encode()) > MAX_REQUEST_BYTES - REQUEST_ENVELOPE_BYTES:
        if arguments.send:
            raise CliError(f"{arguments.file}: too large to send ({len(text.encode())} bytes; a request carries "
                           f"{MAX_REQUEST_BYTES}): leave out --send, and put the file in one of the service's data "
                           "directories")
        return {"path": str(path.resolve())}
    return fields


# -- running -------------------------------------------------------------------------


ESTOP_NOT_CONFIRMED = "E-STOP NOT CONFIRMED: use the hardware E-stop"
"""Said when an ``estop`` got no ok reply, unanswered or refused: nothing says it is latched."""


def run_client_command(arguments: argparse.Namespace, cmd: str, fields: dict[str, Any]) -> int:
    """Send one command, print the reply; the exit status says ok / refused / no answer.
    With ``--wait``, then wait for the motion to end (:func:`wait_until_at_rest`)."""
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # zmq: not for --help

    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    waits = getattr(arguments, "wait", False)
    try:
        with client:
            since = newest_event_t(client) if waits else None
            reply = client.request(cmd, **fields)
            refusal = reply.get("error") if not reply.get("ok") else reply.get("refusal")  # a validate_*'s "not valid"
            if arguments.json:
                print(json.dumps(reply))
            elif refusal is None:
                if cmd == "status":
                    print(f"{'service':<15}{arguments.api} (from {arguments.origins['api']})")
                print(format_ok_reply(cmd, reply, fields), flush=True)
            else:
                print(format_error_reply({"error": refusal}), file=sys.stderr)
            if refusal is not None:
                if cmd == "estop":  # refused (loop_silent: only queued, send_failed, …): not latched
                    print(f"hexactl estop: {ESTOP_NOT_CONFIRMED}", file=sys.stderr)
                return EXIT_REFUSED
            return wait_until_at_rest(client, cmd, reply, since) if waits else EXIT_OK
    except ServiceUnavailable as error:
        print(f"hexactl {arguments.command}: {error}", file=sys.stderr)
        if cmd == "estop":
            print(f"hexactl estop: {ESTOP_NOT_CONFIRMED}", file=sys.stderr)
        return EXIT_NO_ANSWER


WAIT_POLL_S = 0.1
WAIT_SLACK_S = 30.0
"""``--wait`` gives up when a motion has gone on WAIT_SLACK_S longer than its plan said
(the reply's ``duration``, telemetry's ``remaining_s``), a stuck platform: it waits, it
does not judge time. A sequence that goes on from waypoint to waypoint is progress."""


STARTED_BY = {"move": "move", "play": "sequence_started", "resume": "resume", "wave": "wave_started",
              "jog": "jog_started"}
"""The loop's event that a command's motion started with (the API command → the event's code)."""


def newest_event_t(client: Any) -> float | None:
    """When the loop's newest event happened (telemetry's ``t``; None: none yet)."""
    events = client.request("status")["status"].get("events") or []
    return events[-1]["t"] if events else None


def wait_until_at_rest(client: Any, cmd: str, reply: dict[str, Any], since: float | None = None) -> int:
    """``--wait``: poll the service until the platform is at rest and no sequence plays.
    0 then; 1 (saying why) when a fault, an E-stop or a disable ended the motion, the
    sequence is paused, the motion goes on well past its plan, it came to rest short of
    the reply's ``goal`` (stopped), or the sequence or wave ended before its end. What the loop recorded after the motion's own start
    (the events after ``since``, the newest before ``cmd`` was sent) names the cause and who
    sent it."""
    deadline = time.monotonic() + float(reply.get("duration") or 0.0) + WAIT_SLACK_S
    while True:
        status = client.request("status")["status"]
        sequence = status.get("sequence")
        remaining_s = status.get("remaining_s") or 0.0
        if remaining_s > 0 or (sequence and sequence["phase"] == "dwelling"):  # a plan still running: progress
            deadline = max(deadline, time.monotonic() + remaining_s + WAIT_SLACK_S)
        problem = None
        if status["state"] != "enabled":
            faults = "; ".join(fault["message"] for fault in status.get("faults") or [])
            problem = (f"the motion ended: the controller is {status['state']}" + (f" ({faults})" if faults else "")
                       + ("; once its cause is dealt with, `hexactl reset`, then `hexactl enable`"
                          if status["state"] in ("fault", "estop") else ""))
        elif sequence and sequence["phase"] == "paused":
            problem = f"sequence {sequence['name']} is paused: `hexactl resume` or `hexactl abort`"
        elif status["motion"] == "holding" and sequence is None:
            if not (problem := _short_of_goal(reply.get("goal"), status["pose_command"]) or _cut_short(cmd, status)):
                return EXIT_OK
        elif time.monotonic() > deadline:
            problem = f"still moving {WAIT_SLACK_S:g} s after its plan said it would be at rest"
        if problem:
            print(f"hexactl {cmd.replace('_', '-')}: {problem}{since_then(status, cmd, since)}", file=sys.stderr)
            return EXIT_REFUSED
        time.sleep(WAIT_POLL_S)


def since_then(status: dict[str, Any], cmd: str, since: float | None) -> str:
    """What the loop recorded after ``cmd``'s motion started (the first event of its kind
    after ``since``), newest last, with who sent it and how long ago: "" if nothing."""
    events = [event for event in status.get("events") or [] if since is None or event["t"] > since]
    started = next((n for n, event in enumerate(events) if event["code"] == STARTED_BY.get(cmd)), None)
    if started is None:  # its start has left the record's events: what followed it cannot be told apart
        return ""
    told = [event_text(event, status["t"]) for event in events[started + 1:]]
    return f"\n  the service recorded since it started: {'; '.join(told)}" if told else ""


def _cut_short(cmd: str, status: dict[str, Any]) -> str | None:
    """Why the sequence (``play``, ``resume``) or the wave that ``cmd`` set going, now over,
    did not run to its end (None: it did, or ``cmd`` sets neither going). Neither has a
    goal to come to rest short of: a stop or an abort left a sequence at rest on a pose
    of its own, and ``play --wait && next-step`` went on as if it had finished."""
    if cmd in ("play", "resume"):
        last = status.get("last_sequence")
        if last and last["status"] != "finished":
            return f"sequence {last['name']} ended {last['status']}, before its end"
    elif cmd == "wave":
        wave = status.get("wave") or {}
        if wave.get("phase") not in (None, "finished"):
            return wave_ended_message(wave["phase"], wave.get("cycle"), wave.get("cycles"))
    return None


def _short_of_goal(goal: list[float] | None, pose: list[float]) -> str | None:
    """Why a motion at rest at ``pose`` did not end on ``goal`` (None: it did, or has none)."""
    if goal is None or max(abs(at - aim) for at, aim in zip(pose, goal)) <= GOAL_TOLERANCE:
        return None
    return f"stopped short of its goal, at {pose_text(pose)}"


def run_keys(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.security import create_keys

    check_writable(arguments.out, folder=True)
    try:
        made = create_keys(arguments.out, arguments.name)
    except ValueError as error:
        raise CliError(f"--name: {error}") from None
    except OSError as error:
        raise write_failed(arguments.out, error) from None
    print(f"server: --curve-secret {made['server_secret']} --curve-clients {made['clients_dir']}")
    print(f"client: --curve-server {made['server_public']} --curve-client {made['client_secret']}")
    print("keep the .key_secret files private; copy a client's .key into the clients directory to allow it")
    return EXIT_OK


def run_serve(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.security import CurveServerKeys, SecurityError
    from hexactl.application.service import ServiceConfig, ServiceError, run_service  # heavy: only for serve

    if (arguments.curve_secret is None) != (arguments.curve_clients is None):
        raise CliError("give both --curve-secret and --curve-clients, or neither")
    if arguments.can is not None:
        from hexactl.adapters.can.transport import BusSpecError, in_process_note, parse_bus_spec

        with contextlib.suppress(BusSpecError):  # the service refuses it, saying why
            if note := in_process_note(parse_bus_spec(arguments.can)):
                print(f"hexactl serve: --can {note}", file=sys.stderr)
    for directory in arguments.data_dir or ():  # the service says "no such directory" of any that is none
        if directory.exists() and not directory.is_dir():
            raise CliError(f"--data-dir {directory}: {'is a file' if directory.is_file() else 'exists'}, not a "
                           "directory: give a directory")
    restored = [("--frames", arguments.frames, "no frames and no soft limits (set_frames keeps them there)")]
    if arguments.calibration is None:  # else the kept calibration is not read at start
        restored.append(("--keep-calibration", arguments.keep_calibration,
                         "the nominal geometry (a calibration loaded is kept there)"))
    for option, named, what in restored:
        if named is not None and named.is_dir():  # the service's "cannot read", and "remove the file", misled
            raise CliError(f"{option} {named} is a directory: name the file the service keeps there, e.g. "
                           f"{named / ('frames.toml' if option == '--frames' else 'active_calibration.toml')}")
        # A missing directory, or a link to nothing (a disk not mounted), refuses the start.
        if named is not None and named.parent.is_dir() and not named.exists() and not named.is_symlink():
            # The first start with a new file is legitimate; a mistyped name must not pass unseen.
            print(f"hexactl serve: {option} {named}: no such file yet: starting with {what}; if you meant another "
                  "file, stop the service and correct the name", file=sys.stderr)
    curve = CurveServerKeys(arguments.curve_secret, arguments.curve_clients) if arguments.curve_secret else None
    config = ServiceConfig(
        config_path=arguments.config,
        calibration_path=arguments.calibration,
        can=arguments.can,
        rate_hz=arguments.rate,
        api_endpoint=arguments.api,
        telemetry_endpoint=arguments.telemetry,
        telemetry_rate_hz=arguments.telemetry_rate,
        data_dirs=tuple(arguments.data_dir) if arguments.data_dir else None,
        curve=curve,
        fifo_priority=None if arguments.no_realtime else arguments.fifo,
        lock_memory=not arguments.no_realtime,
        log_level=arguments.log_level,
        frames_path=arguments.frames,
        kept_calibration_path=arguments.keep_calibration,
        dashboard_http=checked_http(arguments.dashboard),
        stream_endpoint=arguments.stream,
        stream_udp=udp_address(arguments.stream_udp) if arguments.stream_udp else None,
    )
    try:
        return run_service(config)  # it ends the process, with the service's exit status
    except (ServiceError, SecurityError) as error:
        raise CliError(str(error)) from None


# -- output --------------------------------------------------------------------------


def format_ok_reply(cmd: str, reply: dict[str, Any], fields: dict[str, Any] | None = None) -> str:
    """A successful reply for people: the telemetry for ``status``, else ``ok``, what the
    service said, and the reply's figures; for a move, its whole goal (and when it differs
    from the requested pose, ``fields``, the request's, why)."""
    if cmd == "status":
        return (format_telemetry(reply["status"], reply.get("calibration_source")) + "\n"
                + accuracy_line(reply.get("predicted_accuracy")) + _identification_warnings(reply, "calibration_warnings"))
    if "frames" in reply:
        return "\n".join([f"ok: {reply.get('message') or 'frames'}"] + [f"{label:<15}{text}" for label, text in
                                                                       frames_lines({"frames": reply["frames"]})])
    said = [reply["message"]] if reply.get("message") else []
    fields = fields or {}
    requested, goal = fields.get("pose"), reply.get("goal")
    projected = (not (fields.get("relative") or fields.get("frame")) and requested is not None and goal is not None
                 and any(abs(a - b) > GOAL_TOLERANCE for a, b in zip(goal, requested)))  # an absolute goal moved
    if cmd == "validate_pose":  # the whole goal, whatever was asked: what a move from here would run to
        where = "relative to the zero posture" + ("; projected onto the locked leg's constraint" if projected else "")
        said.append(f"valid, nothing moved: goal {pose_text(goal)} ({where})")
        if reply.get("tool_goal") is not None:
            said.append(f"tool {pose_text(reply['tool_goal'])} (in the work frame)")
    elif fields.get("relative") or fields.get("frame"):
        said.append(f"goal {pose_text(goal)} (relative to the zero posture)")
        if reply.get("tool_goal") is not None:
            said.append(f"tool {pose_text(reply['tool_goal'])} (in the work frame)")
    elif projected:
        said.append(f"goal {pose_text(goal)} (projected onto the locked leg's constraint)")
    elif cmd == "move" and goal is not None:
        # Whole, every time: an absolute pose sets the axes not given to 0, and "move z=50" after
        # "move x=100" took x back 100 mm with only "moving; 1.12 s" said (found from outside).
        said.append(f"goal {pose_text(goal)} (relative to the zero posture; axes not given are 0: --relative keeps "
                    "them)")
    if source := (fields or {}).get("source"):
        said.append(f"read from {source} here and sent")
    if cmd == "validate_sequence":
        said.append(f"valid, nothing moved: it ends at {pose_text(goal)} (relative to the zero posture)")
    if "waypoints" in reply:
        said.append(f"{reply['waypoints']} waypoint{'' if reply['waypoints'] == 1 else 's'}")
    if corrections := reply.get("lock_corrections_mm"):
        farthest = max(range(len(corrections)), key=corrections.__getitem__)
        said.append(f"projected onto the locked leg's constraint: waypoints move by up to "
                    f"{corrections[farthest]:.3f} mm (waypoint {farthest + 1})")
    if reply.get("duration") is not None:
        said.append(f"{reply['duration']:.2f} s")
    if cmd == "validate_calibration":
        said.append(f"nothing loaded: to load this very calibration, --expected-id {reply['calibration_id']}")
    elif "change_mm" in reply:
        said.append(f"set-points change by up to {reply['change_mm']:.3f} mm")
    if "records" in reply:
        said.append(f"{reply['records']} records of {reply['name']} ({reply['status']}) written to {reply['path']}")
    return "ok" + (": " + "; ".join(said) if said else "") + _identification_warnings(reply, "warnings")


def _identification_warnings(reply: dict[str, Any], field: str) -> str:
    """A calibration's identification warnings in ``reply[field]`` (weakly determined, the
    instrument's frame), as calibrate printed them: a line each."""
    return "".join(f"\nwarning: when identified: {warning}" for warning in reply.get(field) or [])


def accuracy_line(accuracy: dict[str, Any] | None) -> str:
    """The predicted accuracy at the tool point, for people."""
    if accuracy is None:
        return f"{'accuracy':<15}not predicted (no calibration covariance: calibrate)"
    x, y, z = accuracy["position_axes_mm"]
    return (f"{'accuracy':<15}{accuracy['position_mm']:.3f} mm (x {x:.3f}, y {y:.3f}, z {z:.3f}), "
            f"{accuracy['orientation_deg']:.4f}° predicted 1σ at the tool point")


def format_error_reply(reply: dict[str, Any]) -> str:
    """An error reply for people: code and message, then each violation or problem the
    details list that the message does not already say."""
    error = reply.get("error") or {}
    message = str(error.get("message"))
    lines = [f"error {error.get('code')}: {message}"]
    details = error.get("details")
    items = details.get("violations", []) if isinstance(details, dict) else details if isinstance(details, list) else []
    for item in items:
        text = item.get("message") if isinstance(item, dict) else item
        if isinstance(text, str) and text not in message:
            lines.append(f"  {text}")
    if error.get("code") in _FILE_ERRORS:
        directories = details.get("data_directories") if isinstance(details, dict) else None
        if directories:
            lines.append(f"  the service's data directories: {', '.join(directories)}")
        lines.append(f"  {_FILE_ERRORS[error['code']]}")
    return "\n".join(lines)


_FILE_ERRORS = {
    "forbidden_path": "the service reads and writes files only in its data directories (hexactl serve --data-dir DIR): "
                      "name a file there, or copy yours into one of them",
    "file_not_found": "check the name: a relative name is looked up in each data directory, then in the service's "
                      "working directory",
}
"""What to do about a file refused: the API's codes for paths."""
