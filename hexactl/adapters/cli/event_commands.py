"""``hexactl events``: what the control loop did and who sent the command behind it.

The service answers ``events`` (docs/api.md) with the loop's kept events (its latest 64),
each numbered. ``events`` prints the last ``--last`` of them, oldest first, and exits;
``--follow`` then asks for those numbered after the last it printed, every
:data:`FOLLOW_POLL_S`, and prints each once as it comes, until Ctrl-C, like
``journalctl -f``; so a burst of events is printed whole. Should more come between two
asks than the loop keeps, a line says how many were missed (the service's log has them).
Each line: this host's clock when it happened (the reply's age aside), the code, the
message and the sender.

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

from hexactl.adapters.cli.common import connect, positive_int
from hexactl.adapters.cli.service_commands import (
    EXIT_NO_ANSWER,
    EXIT_OK,
    EXIT_REFUSED,
    client_parser,
    format_error_reply,
)

EXIT_INTERRUPTED = 130
FOLLOW_POLL_S = 0.1
"""How often ``--follow`` asks for new events (the loop keeps 64: a burst of more within
this is the only way to miss one)."""
DEFAULT_LAST = 20


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    events = subparsers.add_parser(
        "events", parents=[client_parser()], help="what the control loop did, and who sent the command behind it",
        description="Print the control loop's latest events, oldest first: when (this host's clock), what, and who "
                    "sent the command behind it. With --follow, then each new one as it comes, until Ctrl-C.",
    )
    events.add_argument("--last", type=positive_int, default=DEFAULT_LAST, metavar="N",
                        help=f"how many of the latest to print first (default {DEFAULT_LAST}; the loop keeps 64)")
    events.add_argument("--follow", "-f", action="store_true", help="go on printing each new event until Ctrl-C")
    events.epilog = "--json: one JSON event a line, with its time as this host's clock reads it (at: Unix s)."
    events.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Exit 0; 1 when the service refuses; 2 when it does not answer within ``--timeout``; 130 after Ctrl-C."""
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # zmq: not for --help

    try:
        with connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout) as client:
            after, first, run = 0, True, None
            while True:
                reply = client.request("events", after=after)
                received = time.time()
                if not reply.get("ok"):
                    print(format_error_reply(reply), file=sys.stderr)
                    return EXIT_REFUSED
                if run is not None and reply.get("run") != run:  # numbered from 1 again, however many came since
                    print("hexactl events: the service has restarted: its events from the start", file=sys.stderr)
                    after, first, run = 0, False, reply.get("run")
                    continue
                run = reply.get("run")
                shown = reply["events"][-arguments.last:] if first else reply["events"]
                if reply["missed"] and not first:
                    print(f"hexactl events: {reply['missed']} events came and went between two asks (the service's "
                          "log has them)", file=sys.stderr)
                for event in shown:
                    print(_line(event, received - (reply["t"] - event["t"]), arguments.json), flush=True)
                after, first = reply["last"], False
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


def _line(event: dict[str, Any], at: float, as_json: bool) -> str:
    """``event`` that happened at ``at`` (Unix s, this host's clock) as a line of text or JSON."""
    if as_json:
        return json.dumps({**event, "at": round(at, 3)})
    sender = f"  (sent by {event['sender']})" if event.get("sender") else ""
    clock = datetime.fromtimestamp(at).strftime("%H:%M:%S.%f")[:-5]
    return f"{clock}  {event['code']:<20} {event['message']}{sender}"
