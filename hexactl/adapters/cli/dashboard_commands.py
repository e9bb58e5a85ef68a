"""``hexactl dashboard``: the browser dashboard of a running service."""

from __future__ import annotations

import argparse
import functools

from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT, DEFAULT_TELEMETRY_ENDPOINT
from hexactl.adapters.cli.common import CliError, client_endpoint, connect, connection_parser, whole_number

DEFAULT_HTTP = "127.0.0.1:8080"
"""Where the dashboard is served unless told (``--http``; ``serve --dashboard``, ``demo --dashboard``)."""


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    dashboard = subparsers.add_parser(
        "dashboard", parents=[connection_parser()], help="the browser dashboard of a running service",
        description="Serve a web page on this machine that shows the platform in 3D with live plots and has every "
        "operator action (enable, move with a validated preview, jog while a button is held, sequences, leg-lock, "
        "frames, calibration, the recorder, E-stop on the button and the Escape key). It speaks only the service's "
        "public API and telemetry, local or remote (CURVE keys as for any client). Open the printed URL.",
    )
    dashboard.add_argument("--http", default=DEFAULT_HTTP, metavar="HOST:PORT",
                           help=f"where the page is served (default {DEFAULT_HTTP}; loopback only: tunnel to reach it "
                           "from elsewhere; port 0: any free port)")
    dashboard.add_argument("--api", type=client_endpoint, metavar="ENDPOINT", help="the service's command endpoint (default $HEXACTL_API, else "
                           f"the client file's api, else {DEFAULT_API_ENDPOINT})")
    dashboard.add_argument("--telemetry", type=client_endpoint, metavar="ENDPOINT", help="telemetry endpoint (default $HEXACTL_TELEMETRY, else "
                           f"the client file's telemetry, else {DEFAULT_TELEMETRY_ENDPOINT})")
    dashboard.add_argument("--log-level", default="warning", choices=("debug", "info", "warning", "error"))
    dashboard.add_argument("--exit-with", type=whole_number, metavar="PID", help=argparse.SUPPRESS)  # serve --dashboard's
    dashboard.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import TelemetrySubscriber
    from hexactl.adapters.web.bridge import ServiceEndpoints  # starlette and uvicorn: only for this command
    from hexactl.adapters.web.server import DashboardError, HttpAddress, run_dashboard

    address = HttpAddress.parse(checked_http(arguments.http))
    with connect(TelemetrySubscriber, arguments.telemetry, arguments) as probe:  # bad CURVE options: say so now
        curve = probe.curve is not None
    endpoints = ServiceEndpoints(arguments.api, arguments.telemetry, arguments.timeout,
                                 functools.partial(_connect, arguments), curve)
    try:
        return run_dashboard(address, endpoints, arguments.log_level, arguments.exit_with)
    except DashboardError as error:
        raise CliError(str(error)) from None


def checked_http(text: str | None) -> str | None:
    """``--http``/``--dashboard``'s HOST:PORT, checked (loopback only); CliError otherwise."""
    if text is None:
        return None
    from hexactl.adapters.web.server import DashboardError, HttpAddress

    try:
        HttpAddress.parse(text)
    except DashboardError as error:
        raise CliError(str(error)) from None
    return text


def _connect(arguments: argparse.Namespace, kind: type, endpoint: str, **options: object) -> object:
    return connect(kind, endpoint, arguments, **options)

