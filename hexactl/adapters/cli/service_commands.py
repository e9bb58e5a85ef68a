"""``hexactl serve``, the clients of a running service (``status``, ``enable``, ``move``, …),
``hexactl monitor`` and ``hexactl keys``.

Client commands print the reply (human-readable, or the raw JSON with ``--json``) and
exit 0 when the service carried the command out, 1 when it refused it (an error
reply), 2 when nobody answered within ``--timeout`` or the arguments are bad.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT, DEFAULT_TELEMETRY_ENDPOINT, DEFAULT_TELEMETRY_RATE_HZ
from hexactl.adapters.cli.common import CliError, connect, connection_parser, pose_argument, positive_float
from hexactl.kinematics.axes import POSE_AXES

EXIT_OK, EXIT_REFUSED, EXIT_NO_ANSWER = 0, 1, 2
MONITOR_INTERVAL_S = 0.1
_CLEAR_SCREEN = "\x1b[H\x1b[2J"

RequestBuilder = Callable[[argparse.Namespace], tuple[str, dict[str, Any]]]
"""Arguments → (command, request fields)."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    _register_serve(subparsers, common)
    client = _client_parser()

    def command(name: str, help_text: str, build: RequestBuilder | str) -> argparse.ArgumentParser:
        """A client sub-command sending what ``build`` makes of the arguments (a bare
        command name: no fields)."""
        make = (lambda arguments: (build, {})) if isinstance(build, str) else build
        parser = subparsers.add_parser(name, parents=[client], help=help_text, description=help_text)
        parser.set_defaults(run=lambda arguments: run_client_command(arguments, *make(arguments)))
        return parser

    command("status", "the running service's state (one telemetry record)", "status")
    _register_monitor(subparsers)
    command("enable", "energise the actuators; the platform holds its pose", "enable")
    command("disable", "de-energise the actuators (at rest only: stop first)", "disable")
    move = command("move", "move to a pose relative to the zero posture", _move_request)
    move.add_argument("pose", metavar="POSE", type=pose_argument, help="X,Y,Z,ROLL,PITCH,YAW (mm, deg) or axis=value pairs, e.g. z=50,yaw=5")
    pace = move.add_mutually_exclusive_group()
    pace.add_argument("--duration", type=positive_float, metavar="S", help="minimum duration of the move, s")
    pace.add_argument("--speed", type=positive_float, metavar="F", help="fraction (0, 1] of the velocity limits")
    move.epilog = "Put -- before a pose that starts with a minus sign."
    command("stop", "halt any motion smoothly and stay enabled", "stop")
    play = command("play", "play a sequence: a built-in name or a file", _play_request)
    play.add_argument("sequence", metavar="SEQUENCE", help="built-in name (x_sweep, y_rotation, compound) or a sequence file in a data directory of the service")
    command("pause", "pause the playing sequence", "pause")
    command("resume", "resume the paused sequence", "resume")
    command("abort", "abandon the playing sequence (halts smoothly)", "abort")
    leg_lock = command("leg-lock", "lock one leg at its current length (leg-lock calibration mode)", _leg_lock_request)
    leg_lock.add_argument("leg", type=int, choices=range(1, 7), metavar="N", help="leg 1–6")
    command("unlock", "release the locked leg", "leg_unlock")
    load = command("load-calibration", "switch the running service to a calibration file", _load_calibration_request)
    load.add_argument("file", metavar="FILE", help="calibration TOML")
    load.add_argument(
        "--send", action="store_true",
        help="read FILE here and send its content (for a service on another machine); default: the service reads it from its data directories",
    )
    command("rollback-calibration", "return to the calibration active before the last load", "rollback_calibration")
    save = command("save-recording", "write the last sequence's dwell records as CSV on the service's machine", _save_recording_request)
    save.add_argument("file", metavar="FILE", help="new CSV file in a data directory of the service (never overwritten)")
    command("estop", "emergency stop: every actuator stops and holds at once", "estop")
    command("reset", "clear faults and an emergency stop whose cause is gone", "reset")

    keys = subparsers.add_parser(
        "keys", help="make CURVE keys for a service bound beyond localhost",
        description="Make a client key pair (ZeroMQ certificates) in DIR, and the server's unless DIR has it, and allow "
        "the client in DIR/clients. "
        "Serve with --curve-secret DIR/server.key_secret --curve-clients DIR/clients; connect with "
        "--curve-server DIR/server.key --curve-client DIR/NAME.key_secret.",
    )
    keys.add_argument("--out", required=True, type=Path, metavar="DIR")
    keys.add_argument("--name", default="client", help="the client's name (default client); run again with another name to add a client")
    keys.set_defaults(run=run_keys)


def _register_monitor(subparsers: argparse._SubParsersAction) -> None:
    monitor = subparsers.add_parser(
        "monitor", parents=[connection_parser()], help="live view of the service's telemetry",
        description="Show the running service's telemetry, refreshed in place about 10 times a second (Ctrl-C ends).",
    )
    monitor.add_argument("--telemetry", default=DEFAULT_TELEMETRY_ENDPOINT, metavar="ENDPOINT", help=f"telemetry endpoint (default {DEFAULT_TELEMETRY_ENDPOINT})")
    monitor.add_argument("--once", action="store_true", help="print one record and exit")
    monitor.add_argument("--json", action="store_true", help="print records as JSON, one per line")
    monitor.set_defaults(run=run_monitor)


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
        "logged; the log and status say what it got. SIGINT/SIGTERM brake the platform to rest, disable the "
        "actuators and stop, within 10 s."
    )
    serve.add_argument("--can", metavar="SPEC", help="CAN bus of real actuators, e.g. socketcan:can0 (default: the simulator)")
    serve.add_argument("--calibration", metavar="FILE", help="start with this calibration instead of the --config geometry")
    serve.add_argument("--rate", type=int, choices=(250, 500, 1000), default=500, metavar="HZ",
                       help="control loop rate: 250, 500 (default) or 1000 Hz (the protocol's rates)")
    realtime = serve.add_mutually_exclusive_group()
    realtime.add_argument("--fifo", type=int, choices=range(2, 100), default=DEFAULT_FIFO_PRIORITY, metavar="PRIO",
                          help=f"SCHED_FIFO priority 2-99 of the loop (default {DEFAULT_FIFO_PRIORITY}: real-time is the "
                          "default, --no-realtime turns it off); PRIO-1 for the simulator's thread, which shares the "
                          f"loop's GIL; the API process's threads on the way of a stop get nice {API_URGENT_NICENESS}; "
                          "capped at RLIMIT_RTPRIO without CAP_SYS_NICE")
    realtime.add_argument("--no-realtime", action="store_true",
                          help="normal scheduling and no memory locking, even with the privilege")
    serve.add_argument("--mlock", action="store_true",
                       help="accepted for compatibility: the memory is locked by default (--no-realtime: not)")
    serve.add_argument("--api", default=DEFAULT_API_ENDPOINT, metavar="ENDPOINT", help=f"command endpoint (default {DEFAULT_API_ENDPOINT})")
    serve.add_argument("--telemetry", default=DEFAULT_TELEMETRY_ENDPOINT, metavar="ENDPOINT", help=f"telemetry endpoint (default {DEFAULT_TELEMETRY_ENDPOINT})")
    serve.add_argument("--telemetry-rate", type=positive_float, default=DEFAULT_TELEMETRY_RATE_HZ, metavar="HZ", help=f"telemetry records per second (default {DEFAULT_TELEMETRY_RATE_HZ:g})")
    serve.add_argument(
        "--data-dir", action="append", type=Path, metavar="DIR",
        help="directory requests may read calibration and sequence files from and write recordings to "
        "(repeatable; default: ./recordings, ./calibrations, ./sequences and the config file's directory)",
    )
    serve.add_argument("--curve-secret", type=Path, metavar="FILE", help="CURVE server secret key (needed to bind beyond localhost)")
    serve.add_argument("--curve-clients", type=Path, metavar="DIR", help="directory of the client public keys allowed in")
    serve.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def _client_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(add_help=False, parents=[connection_parser()])
    parser.add_argument("--api", default=DEFAULT_API_ENDPOINT, metavar="ENDPOINT", help=f"the service's command endpoint (default {DEFAULT_API_ENDPOINT})")
    parser.add_argument("--json", action="store_true", help="print the raw JSON reply")
    return parser


# -- requests from arguments ---------------------------------------------------------


def _move_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    pace = {name: getattr(arguments, name) for name in ("duration", "speed") if getattr(arguments, name) is not None}
    return "move", {"pose": arguments.pose, **pace}


def _leg_lock_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    return "leg_lock", {"leg": arguments.leg}


def _play_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    return "play", {"sequence": _service_path(arguments.sequence)}


def _save_recording_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    return "save_recording", {"path": _service_path(arguments.file, new=True)}


def _load_calibration_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    if arguments.send:
        try:
            return "load_calibration", {"toml": Path(arguments.file).read_text(encoding="utf-8")}
        except (OSError, UnicodeDecodeError) as error:
            raise CliError(f"{arguments.file}: cannot read: {error}") from None
    return "load_calibration", {"path": _service_path(arguments.file)}


def _service_path(text: str, *, new: bool = False) -> str:
    """A path to a file here (an existing one; with ``new``, one to create in an existing
    directory) is sent absolute, since the service's working directory may differ from
    ours; anything else (a built-in name, a path in the service's data directories) as
    typed."""
    path = Path(text)
    here = path.parent.is_dir() if new else path.is_file()
    return str(path.resolve()) if here else text


# -- running -------------------------------------------------------------------------


def run_client_command(arguments: argparse.Namespace, cmd: str, fields: dict[str, Any]) -> int:
    """Send one command, print the reply; the exit status says ok / refused / no answer."""
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # zmq: not for --help

    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    try:
        with client:
            reply = client.request(cmd, **fields)
    except ServiceUnavailable as error:
        print(f"hexactl {arguments.command}: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER
    if arguments.json:
        print(json.dumps(reply))
    elif reply.get("ok"):
        print(format_ok_reply(cmd, reply))
    else:
        print(format_error_reply(reply), file=sys.stderr)
    return EXIT_OK if reply.get("ok") else EXIT_REFUSED


def run_monitor(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import ServiceUnavailable, TelemetrySubscriber

    try:
        with connect(TelemetrySubscriber, arguments.telemetry, arguments) as telemetry:
            while True:
                record = telemetry.receive(arguments.timeout)
                text = json.dumps(record) if arguments.json else format_telemetry(record)
                if arguments.once:
                    print(text)
                    return EXIT_OK
                print(text if arguments.json else _CLEAR_SCREEN + text, flush=True)
                time.sleep(MONITOR_INTERVAL_S)  # CONFLATE keeps the newest record meanwhile
    except ServiceUnavailable as error:
        print(f"hexactl monitor: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER


def run_keys(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.security import create_keys

    try:
        made = create_keys(arguments.out, arguments.name)
    except (FileExistsError, OSError) as error:
        raise CliError(str(error)) from None
    print(f"server: --curve-secret {made['server_secret']} --curve-clients {made['clients_dir']}")
    print(f"client: --curve-server {made['server_public']} --curve-client {made['client_secret']}")
    print("keep the .key_secret files private; copy a client's .key into the clients directory to allow it")
    return EXIT_OK


def run_serve(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.security import CurveServerKeys, SecurityError
    from hexactl.application.service import ServiceConfig, ServiceError, run_service  # heavy: only for serve

    if (arguments.curve_secret is None) != (arguments.curve_clients is None):
        raise CliError("give both --curve-secret and --curve-clients, or neither")
    curve = CurveServerKeys(arguments.curve_secret, arguments.curve_clients) if arguments.curve_secret else None
    config = ServiceConfig(
        config_path=Path(arguments.config) if arguments.config else None,
        calibration_path=Path(arguments.calibration) if arguments.calibration else None,
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
    )
    try:
        return run_service(config)  # it ends the process, with the service's exit status
    except (ServiceError, SecurityError) as error:
        raise CliError(str(error)) from None


# -- output --------------------------------------------------------------------------


def format_ok_reply(cmd: str, reply: dict[str, Any]) -> str:
    """A successful reply for people: the telemetry for ``status``, else ``ok``, what the
    service said, and the reply's figures."""
    if cmd == "status":
        return format_telemetry(reply["status"])
    said = [reply["message"]] if reply.get("message") else []
    if "waypoints" in reply:
        said.append(f"{reply['waypoints']} waypoints")
    if reply.get("duration") is not None:
        said.append(f"{reply['duration']:.2f} s")
    if "change_mm" in reply:
        said.append(f"set-points change by up to {reply['change_mm']:.3f} mm")
    if "records" in reply:
        said.append(f"{reply['records']} records of {reply['name']} ({reply['status']}) written to {reply['path']}")
    return "ok" + (": " + "; ".join(said) if said else "")


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
    return "\n".join(lines)


def format_telemetry(record: dict[str, Any]) -> str:
    """A telemetry record as an aligned block of text (poses in mm and deg)."""
    loop = record["loop"]
    sequence = record.get("sequence")
    faults = record.get("faults") or []
    lines = [
        ("state", f"{record['state']}, {record['motion']}"),
        ("pose command", _pose_text(record.get("pose_command"))),
        ("pose measured", _pose_text(record.get("pose_measured"))),
        ("leg set-points", _legs_text(record.get("leg_setpoints"))),
        ("leg feedback", _legs_text(record.get("leg_feedback"))),
        ("locked leg", str(record["locked_leg"]) if record.get("locked_leg") else "none"),
        ("calibration", record["calibration_id"]),
        ("sequence", f"{sequence['name']} {sequence['index']}/{sequence['total']} ({sequence['phase']})" if sequence else "none"),
        ("faults", "; ".join(_fault_text(fault) for fault in faults) if faults else "none"),
        ("loop", f"{loop['rate_hz']:g} Hz, {loop['cycles']} cycles, {loop['missed']} missed"),
        ("lateness µs", _percentiles_text(loop["lateness_us"])),
        ("compute µs", _percentiles_text(loop["compute_us"])),
        ("real-time", _realtime_text(record.get("realtime"))),
    ]
    return "\n".join(f"{label:<15}{value}" for label, value in lines)


def _pose_text(pose: list[float] | None) -> str:
    if pose is None:
        return "unknown"
    return "  ".join(f"{axis} {value:9.3f}" for axis, value in zip(POSE_AXES, pose))


def _legs_text(values: list[float | None] | None) -> str:
    if values is None:
        return "unknown"
    return "  ".join(f"L{leg} {'?' if value is None else format(value, '8.3f'):>8}" for leg, value in enumerate(values, start=1))


def _realtime_text(realtime: dict[str, Any] | None) -> str:
    if not realtime:
        return "unknown"
    # Here, not at the top: the module loads pydantic, which the other commands do not need.
    from hexactl.control.realtime import RealtimeReport, describe

    return describe(RealtimeReport(**realtime))


def _fault_text(fault: dict[str, Any]) -> str:
    where = f"leg {fault['leg']}: " if fault.get("leg") else ""
    return f"{where}{fault['code']} ({fault['message']})"


def _percentiles_text(values: dict[str, float]) -> str:
    return f"p50 {values['p50']:.0f}  p99 {values['p99']:.0f}  p99.9 {values['p999']:.0f}  max {values['max']:.0f}"
