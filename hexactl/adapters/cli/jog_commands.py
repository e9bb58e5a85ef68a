"""``hexactl jog``: jog a running service for a while, renewing the deadman, then release.

The service jogs only while its client renews the jog (``jog_deadman_s``, 0.2 s by
default): this command renews it four times per interval for ``--for`` seconds, then
releases it and waits until the platform is at rest. Ctrl-C releases it at once; if this
command dies, the service brakes by itself when the deadman lapses.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from hexactl.adapters.cli.common import checked_number, connect, velocity_argument
from hexactl.adapters.cli.service_commands import (
    EXIT_NO_ANSWER,
    EXIT_REFUSED,
    FRAMES,
    client_parser,
    format_error_reply,
    newest_event_t,
    since_then,
    wait_until_at_rest,
)
from hexactl.adapters.cli.telemetry_text import pose_text
from hexactl.control.bounds import jog_velocity_problem
from hexactl.control.results import JOG_RESTART_ADVICE

RENEWALS_PER_DEADMAN = 4
"""Renewals per deadman interval: three may be late before the platform brakes."""

MAX_JOG_FOR_S = 600.0


def _jog_velocity(text: str) -> list[float]:
    """An argparse ``type``: a velocity to jog at. All zeros would release a jog (the API's
    meaning), not start one: nothing to renew, and the command broke on the reply."""
    velocity = velocity_argument(text)
    if not any(velocity):
        raise argparse.ArgumentTypeError(f"velocity {text!r} is zero on every axis: give a velocity to jog at, "
                                         "e.g. z=5 (to brake to rest: hexactl stop)")
    if problem := jog_velocity_problem(velocity):
        raise argparse.ArgumentTypeError(f"velocity {text!r}: {problem}")
    return velocity


def _for_problem(seconds: float) -> str | None:
    if not 0 < seconds <= MAX_JOG_FOR_S:
        return f"{seconds:g} s: jog for more than 0 s and at most {MAX_JOG_FOR_S:g} s (jog in shorter runs)"
    return None


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    description = ("jog the platform at a velocity for a while: it heads for the first limit ahead (hardware or "
                   "soft) and comes to rest on it; then it is released and brakes to rest")
    jog = subparsers.add_parser("jog", parents=[client_parser()], help=description, description=description)
    jog.add_argument("velocity", metavar="VELOCITY", type=_jog_velocity,
                     help="X,Y,Z,ROLL,PITCH,YAW in mm/s and deg/s, or axis=value pairs, e.g. z=5 or yaw=-1")
    jog.add_argument("--for", dest="for_s", type=checked_number(_for_problem), required=True, metavar="S",
                     help=f"how long to jog, s (at most {MAX_JOG_FOR_S:g}); Ctrl-C releases it sooner")
    jog.add_argument("--frame", choices=FRAMES, default="zero",
                     help="zero: the platform's axes at the zero posture (default); work: the work frame's axes; "
                     "tool: the tool's own axes, turning about the pivot point")
    jog.epilog = ("Exit 0 at rest after the release; 1 if the service refused the jog or a fault ended it. With --json: "
                  "the first reply, then the status at rest, one JSON object per line.")
    jog.set_defaults(run=run_jog)


def run_jog(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # zmq: not for --help

    fields = {"velocity": arguments.velocity, "frame": arguments.frame}
    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    try:
        with client:
            since = newest_event_t(client)
            reply = client.request("jog", **fields)
            if not reply.get("ok"):
                print(format_error_reply(reply), file=sys.stderr)
                return EXIT_REFUSED
            if arguments.json:
                print(json.dumps(reply), flush=True)
            else:
                print(f"jogging (jog {reply['jog']}): heading for {reply['end']}, {_pace(reply['speed'])}", flush=True)
            try:
                refused = _renew(client, fields, reply["jog"], arguments.for_s,
                                 reply["deadman_s"] / RENEWALS_PER_DEADMAN)
            finally:
                client.request("jog", velocity=[0.0] * 6, frame=arguments.frame)
            if refused is not None:
                print(format_error_reply(_in_cli_terms(refused)) + since_then(client.request("status")["status"], "jog",
                                                                                since), file=sys.stderr)
                return EXIT_REFUSED
            waited = wait_until_at_rest(client, "jog", {}, since)
            status = client.request("status")["status"]
            if arguments.json:
                print(json.dumps(status))
                return waited
            print(f"released; at rest at {pose_text(status['pose_command'])}"
                  + (f" (tool {pose_text(status['tool_pose_command'])} in the work frame)"
                     if arguments.frame != "zero" else ""))
            return waited
    except ServiceUnavailable as error:
        print(f"hexactl jog: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER


def _in_cli_terms(refused: dict[str, Any]) -> dict[str, Any]:
    """``refused`` with a jog that has ended said as this command's user acts on it (the
    service's :data:`~hexactl.control.results.JOG_RESTART_ADVICE` is the API's), whatever
    said it (the facade, with the jog and why in its details, or the loop, in its words
    only)."""
    error = refused.get("error") or {}
    message = str(error.get("message") or "")
    if error.get("code") != "jog_ended" or not message.endswith(f": {JOG_RESTART_ADVICE}"):
        return refused
    said = message.removesuffix(f": {JOG_RESTART_ADVICE}") + ": run hexactl jog again to jog on"
    return {**refused, "error": {**error, "message": said}}


def _pace(speed: float) -> str:
    """The jog's pace from its velocity scale (the fraction of the motion limits it runs at)."""
    if speed < 1.0:
        percent = speed * 100  # two significant digits below 10 %: a slow jog is not "0 %"
        share = f"{percent:.0f}" if percent >= 9.95 else f"{percent:.2g}" if percent >= 0.01 else "under 0.01"
        return f"at the velocity asked ({share}% of the motion limits)"
    return "at the motion limits (the velocity asked reaches them)"


CANCELLED_RETRIES = 3
"""Renewals sent again, a renewal period apart, after one a stop cancelled on its way."""


def _renew(client: Any, fields: dict[str, Any], jog: int, for_s: float, every_s: float) -> dict[str, Any] | None:
    """Renew jog ``jog`` every ``every_s`` for ``for_s``; the reply that refused it (None:
    none did). Once it has ended, a stop from anyone (also one that cancelled a renewal on
    its way), a fault or a move ends this command too; only a stall of this machine or the
    service starts a new jog, as the button is still held: a lapse of its deadman, or a
    renewal held up past its deadline (``expired``: not carried out; the next renewal goes
    on, or finds the jog lapsed)."""
    end = time.monotonic() + for_s
    while (left := end - time.monotonic()) > 0:
        time.sleep(min(every_s, left))
        reply = client.request("jog", **fields, renews=jog)
        error = reply.get("error") or {}
        if error.get("code") == "expired":
            continue
        for _ in range(CANCELLED_RETRIES):
            if (reply.get("error") or {}).get("code") != "cancelled":
                break
            # A stop reached the service while this renewal was on its way: "not carried out"
            # is the renewal's, not the jog's (it had run for seconds: found from outside). The
            # next renewal gets the jog's own word: ended, stopped, by whom; sent at once, it may
            # be cancelled as well, while the service still takes what came with the stop.
            time.sleep(every_s)
            reply = client.request("jog", **fields, renews=jog)
        error = reply.get("error") or {}
        if error.get("code") == "jog_ended" and (error.get("details") or {}).get("lapsed"):
            reply = client.request("jog", **fields, restarts=jog)  # refused if a stop came after the lapse
            if reply.get("ok"):  # said: the platform braked to rest and goes on (found from outside: silent)
                print(f"hexactl jog: jog {jog} lapsed (this machine or the service held up its renewals): the "
                      f"platform braked; jogging on as jog {reply['jog']}", file=sys.stderr, flush=True)
        if not reply.get("ok"):
            return reply
        jog = reply["jog"]
    return None
