"""``hexactl events``: what the control loop did and who sent the command behind it.

The loop's latest events come in every telemetry record (docs/api.md, "Telemetry":
``events``, at most 8). ``events`` prints those, oldest first, and exits; ``--follow``
then prints each new one as it comes, until Ctrl-C, like ``journalctl -f``: a burst of
more events than a record carries between two records read shows its last 8 only (the
service's log has them all). Each line: this host's clock when it happened (the
record's age aside), the code, the message and the sender.

Standard library only at the top (start-up: :mod:`hexactl.adapters.cli.common`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from datetime import datetime
from typing import Any

from hexactl.adapters.api.protocol import DEFAULT_TELEMETRY_ENDPOINT
from hexactl.adapters.cli.common import client_endpoint, connect, connection_parser

EXIT_OK, EXIT_NO_ANSWER, EXIT_INTERRUPTED = 0, 2, 130
FOLLOW_POLL_S = 0.02
"""How often ``--follow`` reads the newest record (telemetry is conflated: it skips none of
the 8 events a record carries unless 8 more came within this)."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    events = subparsers.add_parser(
        "events", parents=[connection_parser()], help="what the control loop did, and who sent the command behind it",
        description="Print the control loop's latest events (what a telemetry record carries, at most 8), oldest "
                    "first: when (this host's clock), what, and who sent the command behind it. With --follow, then "
                    "each new one as it comes, until Ctrl-C.",
    )
    # None: main() fills it in from the environment, the client file or the default (cli/endpoints.py).
    events.add_argument("--telemetry", type=client_endpoint, metavar="ENDPOINT", help="telemetry endpoint (default "
                        f"$HEXACTL_TELEMETRY, else the client file's telemetry, else {DEFAULT_TELEMETRY_ENDPOINT})")
    events.add_argument("--follow", "-f", action="store_true", help="go on printing each new event until Ctrl-C")
    events.add_argument("--json", action="store_true", help="one JSON event a line, with its time as this host's "
                        "clock reads it (at: Unix s)")
    events.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Exit 0; 2 when no telemetry arrives within ``--timeout``; 130 after Ctrl-C."""
    from hexactl.adapters.api.client import ServiceUnavailable, TelemetrySubscriber  # zmq: not for --help

    seen: set[tuple[Any, ...]] = set()
    try:
        with connect(TelemetrySubscriber, arguments.telemetry, arguments) as telemetry:
            while True:
                record = telemetry.receive(arguments.timeout)
                received = time.time()
                events = record.get("events") or []
                for event in events:
                    if _key(event) not in seen:
                        print(_line(event, received - (record["t"] - event["t"]), arguments.json), flush=True)
                seen = {_key(event) for event in events}  # the record's window: older ones cannot come back
                if not arguments.follow:
                    return EXIT_OK
                time.sleep(FOLLOW_POLL_S)
    except ServiceUnavailable as error:
        print(f"hexactl events: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER
    except BrokenPipeError:  # the reader left (`hexactl events -f | head`): as `hexactl monitor` does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


def _key(event: dict[str, Any]) -> tuple[Any, ...]:
    return event["t"], event["code"], event["message"], event.get("sender")


def _line(event: dict[str, Any], at: float, as_json: bool) -> str:
    """``event`` that happened at ``at`` (Unix s, this host's clock) as a line of text or JSON."""
    if as_json:
        return json.dumps({**event, "at": round(at, 3)})
    sender = f"  (sent by {event['sender']})" if event.get("sender") else ""
    clock = datetime.fromtimestamp(at).strftime("%H:%M:%S.%f")[:-5]
    return f"{clock}  {event['code']:<20} {event['message']}{sender}"
