"""``hexactl monitor``: the operator's live view of a running service, one keystroke from a stop.

On a terminal it takes the full screen (rich's alternate screen, redrawn in place about ten
times a second) and reads single keys (:data:`KEY_COMMANDS`): each sends its command to the
service at once, from a thread of its own, so that an E-stop never waits behind a redraw;
the reply (ok, or the refusal) shows in the status line. With ``--once``, ``--json`` or an
output that is not a terminal it prints plain records instead (``--json``: one JSON record
a line). Leaving (``q``, Ctrl-C) while the platform moves says so, and how to stop it.

Start-up: rich, zmq and the API client load when the command runs, not when the parser is
built (:mod:`hexactl.adapters.cli.common`).
"""

from __future__ import annotations

import argparse
import json
import os
import select
import sys
import termios
import threading
import time
import tty
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any

from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT, DEFAULT_TELEMETRY_ENDPOINT
from hexactl.adapters.cli.common import client_endpoint, connect, connection_parser
from hexactl.adapters.cli.telemetry_text import (
    NO_FRAMES,
    event_text,
    fault_text,
    format_telemetry,
    frames_lines,
    jog_text,
    leg_states_text,
    link_lines,
    loop_text,
    other_controller_lines,
    percentiles_text,
    realtime_text,
    recording_text,
    remaining_text,
    sequence_text,
    silent_loop_lines,
    stream_input_lines,
    stream_text,
    wave_text,
)
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS

if TYPE_CHECKING:  # loaded when the monitor runs
    from rich.console import RenderableType

    from hexactl.adapters.api.client import HexactlClient

EXIT_OK, EXIT_NO_ANSWER, EXIT_INTERRUPTED = 0, 2, 130
REFRESH_S = 0.1
ESCAPE = "\x1b"
ESCAPE_SEQUENCE_WAIT_S = 0.05
"""After an Escape byte, how long to wait for the rest of a sequence (an arrow key sends
``ESC [ A`` at once): nothing within it, and it was the Escape key."""

KEY_COMMANDS: dict[str, str] = {" ": "stop", ESCAPE: "estop", "e": "estop", "p": "pause", "r": "resume", "x": "reset"}
"""Key → the API command it sends."""
SENT_TO_ANOTHER_SERVICE = ("stop", "estop")
"""The keys' commands sent when the API answers for another service than the one shown:
stopping is never wrong; a reset or a resume of a platform not watched is."""
QUIT_KEY = "q"
LEGEND = "space stop · Esc or e E-STOP · p pause · r resume · x reset · q quit"


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    monitor = subparsers.add_parser(
        "monitor", parents=[connection_parser()], help="live view of the service's telemetry, with keys to stop it",
        description=f"Show the running service's telemetry full screen, redrawn in place; keys: {LEGEND}. "
                    "With --once, --json or output to a pipe or file: plain records.",
    )
    # None: main() fills them in from the environment, the client file or the default (cli/endpoints.py).
    monitor.add_argument("--api", type=client_endpoint, metavar="ENDPOINT", help="the service's command endpoint, for the keys (default "
                         f"$HEXACTL_API, else the client file's api, else {DEFAULT_API_ENDPOINT})")
    monitor.add_argument("--telemetry", type=client_endpoint, metavar="ENDPOINT", help="telemetry endpoint (default $HEXACTL_TELEMETRY, else "
                         f"the client file's telemetry, else {DEFAULT_TELEMETRY_ENDPOINT})")
    monitor.add_argument("--once", action="store_true", help="print one record and exit")
    monitor.add_argument("--json", action="store_true", help="print records as JSON, one per line")
    monitor.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Full screen on a terminal, else plain records; exit 0, 2 when no telemetry
    arrives within ``--timeout`` (plain output only: the screen waits and says so), 130
    after Ctrl-C."""
    if arguments.once or arguments.json or not (sys.stdout.isatty() and sys.stdin.isatty()):
        return _run_plain(arguments)
    return _run_screen(arguments)


# -- plain output ----------------------------------------------------------------------


def _run_plain(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import ServiceUnavailable, TelemetrySubscriber

    record = None
    try:
        with connect(TelemetrySubscriber, arguments.telemetry, arguments) as telemetry:
            while True:
                record = telemetry.receive(arguments.timeout)
                print(json.dumps(record) if arguments.json else format_telemetry(record) + "\n", flush=True)
                if arguments.once:
                    return EXIT_OK
                time.sleep(REFRESH_S)  # CONFLATE keeps the newest record meanwhile
    except ServiceUnavailable as error:
        print(f"hexactl monitor: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER
    except BrokenPipeError:
        # The reader left (`hexactl monitor --json | head`): that ends the output. Stdout
        # goes to /dev/null so that the interpreter's last flush at exit finds no pipe either.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except KeyboardInterrupt:
        say_if_moving(record)
        return EXIT_INTERRUPTED


def say_if_moving(record: dict[str, Any] | None) -> None:
    """One line on stderr if ``record`` (the last one seen) shows the platform moving or a
    sequence playing (not paused): it goes on without the monitor."""
    if record is None:
        return
    sequence = record.get("sequence")
    playing = sequence is not None and sequence["phase"] != "paused"
    if record["motion"] == "holding" and not playing:
        return
    doing = f"a sequence plays ({sequence_text(sequence)})" if playing else f"it is {record['motion']}"
    print(f"hexactl monitor: left while the platform moves ({doing}); it goes on: `hexactl stop` stops it",
          file=sys.stderr)


# -- the full screen ---------------------------------------------------------------------


def _run_screen(arguments: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.live import Live

    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber

    # The screen is the terminal's own size (rich asks the terminal, ioctl), not what
    # COLUMNS and LINES say: a shell, or readline in the process that started this one,
    # may have exported them, stale after a resize (80×24 under a 120×40 tmux pane).
    for name in ("COLUMNS", "LINES"):
        os.environ.pop(name, None)
    record: dict[str, Any] | None = None
    received_at = time.monotonic()
    status = StatusLine(f"keys send commands to {arguments.api}")
    exit_status = EXIT_OK
    with (connect(TelemetrySubscriber, arguments.telemetry, arguments) as telemetry,
          KeyReader(sys.stdin.fileno()) as reader):
        api = lambda: connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)  # noqa: E731
        services = ServiceCheck(api, arguments.api, arguments.telemetry)
        keys = KeyThread(reader, api, status.set, lambda: services.two_services)
        keys.start()
        try:
            with Live(console=Console(), screen=True, auto_refresh=False, redirect_stdout=False, redirect_stderr=False) as live:
                while not keys.quit.is_set():
                    try:
                        record, received_at = telemetry.receive(0), time.monotonic()
                        services.check(record.get("run"))
                    except ServiceUnavailable:  # none new: the last one stays, with its age
                        pass
                    silence_s = time.monotonic() - received_at
                    waiting = (f"no telemetry from {arguments.telemetry} for {silence_s:.0f} s: is `hexactl serve` running there?"
                               if silence_s > arguments.timeout else None)
                    warnings = "\n".join(text for text in (services.two_services, waiting) if text)
                    live.update(view(record, status.text, warnings or None), refresh=True)
                    keys.quit.wait(REFRESH_S)
        except KeyboardInterrupt:
            exit_status = EXIT_INTERRUPTED
        finally:
            keys.stop()  # before the client closes: the thread uses it
    say_if_moving(record)
    return exit_status


class ServiceCheck:
    """Whether the API (``connect()``, at ``api``) answers for the service whose telemetry
    (at ``telemetry``) is shown, by their ``run``: asked in a thread of its own for each new
    run the records name. Found from outside: ``--api`` of one service and the telemetry of
    another (``$HEXACTL_TELEMETRY``, or the default beside another ``--api``) showed the
    one platform while the keys went to the other, and nothing said so."""

    def __init__(self, connect: Callable[[], HexactlClient], api: str, telemetry: str) -> None:
        self._connect, self._api, self._telemetry = connect, api, telemetry
        self._asked: object = _UNASKED  # the telemetry's run compared, or being compared
        self.two_services: str | None = None
        """Set when the two differ: what to show, in place of the keys' other commands."""

    def check(self, telemetry_run: str | None) -> None:
        if telemetry_run != self._asked:
            self._asked = telemetry_run
            threading.Thread(target=self._compare, args=(telemetry_run,), name="hexactl-monitor-runs",
                             daemon=True).start()

    def _compare(self, telemetry_run: str | None) -> None:
        try:
            with self._connect() as client:
                reply = client.request("status")
        except Exception:  # no answer: the keys say so when pressed; asked again with the next run
            self._asked = _UNASKED
            return
        api_run = reply.get("status", {}).get("run") if reply.get("ok") else telemetry_run
        self.two_services = None if api_run == telemetry_run else (
            f"--api {self._api} and --telemetry {self._telemetry} are two different services (run {api_run} answers "
            f"the API, run {telemetry_run} sends what is shown): the keys stop the API's, only space and Esc are sent; "
            "check --api and --telemetry")


_UNASKED = object()


class StatusLine:
    """The status line's text, set by the key thread and read by the drawing one (a str
    reference: swapped whole)."""

    def __init__(self, text: str) -> None:
        self.text = text

    def set(self, text: str) -> None:
        self.text = text


class KeyReader:
    """Single keys from the terminal ``fd``, in cbreak mode (no echo, no line buffering;
    Ctrl-C still interrupts) until :meth:`close` or the ``with`` block's end restores it.

    :raises termios.error: ``fd`` is not a terminal
    """

    def __init__(self, fd: int) -> None:
        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)

    def read(self, timeout_s: float) -> str | None:
        """The next key (:data:`ESCAPE` for the Escape key, the whole sequence for a key
        that sends one), or None if none within ``timeout_s``."""
        if not _readable(self._fd, timeout_s):
            return None
        key = os.read(self._fd, 1)
        if key == ESCAPE.encode() and _readable(self._fd, ESCAPE_SEQUENCE_WAIT_S):
            key += os.read(self._fd, 32)
        return key.decode(errors="replace")

    def close(self) -> None:
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)

    def __enter__(self) -> KeyReader:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None) -> None:
        self.close()


def _readable(fd: int, timeout_s: float) -> bool:
    return bool(select.select([fd], [], [], timeout_s)[0])


class KeyThread(threading.Thread):
    """Reads keys from ``reader`` and sends each one's command as soon as it is read, on a
    connection of its own (``connect()``) from a thread of its own, so that no key waits
    behind another's command (an E-stop behind a ``stop`` the service is slow to answer);
    says what came of each through ``say``. ``quit`` is set when the quit key is read (or
    the thread fails)."""

    def __init__(self, reader: KeyReader, connect: Callable[[], HexactlClient], say: Callable[[str], None],
                 two_services: Callable[[], str | None] = lambda: None) -> None:
        super().__init__(name="hexactl-monitor-keys", daemon=True)
        self._reader = reader
        self._connect = connect
        self._say = say
        self._two_services = two_services
        self._stopping = threading.Event()
        self.quit = threading.Event()

    def stop(self) -> None:
        self._stopping.set()
        self.join()

    def run(self) -> None:
        from hexactl.adapters.api.client import ServiceUnavailable

        try:
            while not self._stopping.is_set():
                key = self._reader.read(REFRESH_S)
                if key == QUIT_KEY:
                    return
                if key is not None:
                    threading.Thread(target=self._send, args=(key, ServiceUnavailable), name="hexactl-monitor-key",
                                     daemon=True).start()
        except Exception as error:  # shown rather than lost with the thread: the keys no longer work
            self._say(f"the keys stopped working ({type(error).__name__}: {error}): use `hexactl stop` / `hexactl estop`")
        finally:
            self.quit.set()


    def _send(self, key: str, unavailable: type[Exception]) -> None:
        if (two := self._two_services()) and KEY_COMMANDS.get(key) not in SENT_TO_ANOTHER_SERVICE:
            self._say(f"{key_name(key)}: not sent: {two}")
            return
        try:
            with self._connect() as client:
                self._say(key_result(key, client, unavailable))
        except Exception as error:  # shown rather than lost with the thread (bad keys, a closed context)
            self._say(f"{key_name(key)}: not sent ({type(error).__name__}: {error}): use `hexactl estop`")


def key_result(key: str, client: HexactlClient, unavailable: type[Exception]) -> str:
    """Send ``key``'s command (:data:`KEY_COMMANDS`) through ``client``: the status line
    saying what came of it (``unavailable``: the client's no-answer exception)."""
    from hexactl.adapters.cli.service_commands import ESTOP_NOT_CONFIRMED, format_error_reply, format_ok_reply

    command = KEY_COMMANDS.get(key)
    if command is None:
        return f"{key_name(key)}: not a key of the monitor ({LEGEND})"
    unconfirmed = f"; {ESTOP_NOT_CONFIRMED}" if command == "estop" else ""
    try:
        reply = client.request(command)
    except unavailable as error:
        return f"{command}: {error}{unconfirmed}"
    if reply.get("ok"):
        return f"{command}: {format_ok_reply(command, reply)}"
    said = format_error_reply(reply).replace("\n", ";")
    return f"{command}: {said}{unconfirmed}"


def key_name(key: str) -> str:
    return {" ": "space", ESCAPE: "Esc"}.get(key, repr(key))


# -- the view ----------------------------------------------------------------------------

_STATE_STYLES = {"enabled": "bold green", "disabled": "yellow", "fault": "bold white on red", "estop": "bold white on red"}


def view(record: dict[str, Any] | None, status: str, waiting: str | None = None) -> RenderableType:
    """The screen for the telemetry ``record`` (None: none yet), the status line and a
    warning that telemetry is missing (``waiting``)."""
    from rich.console import Group
    from rich.text import Text

    # The status line (what a key did) under the legend: a screen too short for the whole
    # record cuts the record's last lines, never the answer to an E-stop key.
    parts: list[RenderableType] = [Text.assemble(("hexactl monitor", "bold"), "   ", (LEGEND, "cyan")),
                                   Text(status, style="bold")]
    if waiting:
        parts.append(Text(waiting, style="bold red"))
    if record is None:
        parts.append(Text("waiting for telemetry …"))
    else:
        parts.extend(_record_view(record))
    return Group(*parts)


def _record_view(record: dict[str, Any]) -> list[RenderableType]:
    from rich.table import Table
    from rich.text import Text

    state = Text.assemble((f" {record['state'].upper()} ", _STATE_STYLES.get(record["state"], "")),
                          f"  {record['motion']}", f"   remaining {remaining_text(record.get('remaining_s'))}")
    poses = Table(box=None, pad_edge=False, header_style="bold")
    poses.add_column("pose")
    for axis, unit in zip(POSE_AXES, POSE_UNITS):
        poses.add_column(f"{axis} {unit}", justify="right")
    framed = record.get("frames") not in (None, NO_FRAMES)
    for label, pose in (("command", record.get("pose_command")), ("measured", record.get("pose_measured")),
                        ("goal", record.get("goal")),
                        *((("tool in work", record.get("tool_pose_command")),) if framed else ())):
        poses.add_row(label, *([f"{value:.3f}" for value in pose] if pose else ["—"] * 6))
    legs = Table(box=None, pad_edge=False, header_style="bold")
    legs.add_column("legs")
    locked = record.get("locked_leg")
    for leg in range(1, 7):
        legs.add_column(f"L{leg} mm" + (" locked" if leg == locked else ""), justify="right")
    for label, values in (("set-point", record.get("leg_setpoints")), ("feedback", record.get("leg_feedback"))):
        legs.add_row(label, *(["—" if value is None else f"{value:.3f}" for value in values] if values else ["—"] * 6))
    loop = record["loop"]
    faults = record.get("faults") or []
    facts = Table.grid(padding=(0, 2))
    facts.add_column(style="bold")
    facts.add_column()
    for label, value in (
        *((label, Text(text, style="bold red")) for label, text in silent_loop_lines(loop)),
        *frames_lines({"frames": record.get("frames")}),
        # Not a row of the table above: a named fault word is wider than a column (an
        # E-stop's wrapped into three lines and pushed the key's result off a 40-line screen).
        ("legs", leg_states_text(record.get("legs"))),
        *((label, Text(text, style="bold red", no_wrap=True, overflow="ellipsis"))
          for label, text in other_controller_lines(record.get("other_controller"))),
        *((label, Text(text, style="bold red" if label.isupper() else "", no_wrap=True, overflow="ellipsis"))
          for label, text in link_lines(record.get("link"))),
        ("locked leg", f"L{locked}" if locked else "none"),
        ("calibration", record["calibration_id"]),
        ("sequence", sequence_text(record.get("sequence"))),
        ("jog", jog_text(record.get("jog"))),
        ("wave", wave_text(record.get("wave"))),
        ("stream", Text(stream_text(record.get("stream"), record.get("last_stream")), no_wrap=True,
                        overflow="ellipsis")),
        *((label, Text(text, style="bold red" if label.isupper() else "", no_wrap=True, overflow="ellipsis"))
          for label, text in stream_input_lines(record.get("stream_input"))),
        ("recording", recording_text(record.get("recording"))),
        # One line each, cut at the screen's edge: a long one (an E-stop names its sender) must
        # not push the key's result off the screen; `hexactl status` prints them whole.
        ("faults", Text("\n".join(fault_text(fault) for fault in faults), style="bold red", no_wrap=True,
                        overflow="ellipsis") if faults else "none"),
        ("last event", Text(event_text(events[-1], record["t"]), no_wrap=True, overflow="ellipsis")
         if (events := record.get("events")) else "none"),
        ("loop", loop_text(loop)),
        ("lateness µs", percentiles_text(loop["lateness_us"])),
        ("compute µs", percentiles_text(loop["compute_us"])),
        ("real-time", realtime_text(record.get("realtime"))),
    ):
        facts.add_row(label, value)
    return [state, poses, legs, facts]

