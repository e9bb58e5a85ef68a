"""Start-up of ``hexactl``: building the parser, ``--help``, and the client commands an
operator types (``status``, ``move``) load none of the heavy modules (numpy, scipy,
pydantic, the calibration, the control loop, the service, the report), so that they start
fast (the time itself is measured by tools/bench_cli_startup.py, not asserted here).

Each check runs in a fresh interpreter, since this one has long imported everything."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hexactl.adapters.cli.common import DeferredParser
from tools.serving import unserved_endpoint

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 120.0  # only turns a hang into a failure
NOBODY = unserved_endpoint()
NO_SERVICE = ["--api", NOBODY, "--timeout", "0.05"]  # nothing listens there: fails fast, exit 2

HEAVY = (
    "numpy", "scipy", "matplotlib", "pydantic", "pydantic_core", "can", "asyncio", "zmq",
    "hexactl.adapters.api.messages", "hexactl.adapters.api.security", "hexactl.adapters.report",
    "hexactl.application", "hexactl.calibration", "hexactl.control", "hexactl.sim", "rich",
)
"""Modules (and their submodules) none of the light commands may load: ``zmq`` only the
commands that talk to the service, ``zmq.auth`` (in ``security``) only with CURVE keys."""

LIGHT = ("hexactl.control", "hexactl.control.results", "hexactl.control.bounds")
"""Of those, modules that import the standard library only, which the CLI reads (the
control loop's :data:`~hexactl.control.results.REPORT_SILENT_S`); were one of them to
import a heavy module, the check would see that one."""


def loaded_after(argv: list[str] | None) -> dict[str, object]:
    """In a fresh interpreter on this tree: build ``hexactl``'s parser (``argv`` None) or
    run ``hexactl ARGV``; its exit status and the loaded modules of :data:`HEAVY`."""
    code = f"""
import contextlib, io, json, sys
from hexactl.adapters.cli.main import build_parser, main
argv = {argv!r}
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    try:
        status = 0 if argv is None and build_parser() else main(argv)
    except SystemExit as exit:
        status = exit.code
heavy = {HEAVY!r}
print(json.dumps({{"status": status,
                   "heavy": sorted(m for m in sys.modules if any(m == h or m.startswith(h + ".") for h in heavy)
                                   and m not in {LIGHT!r})}}))
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.mark.parametrize(("argv", "status", "allowed"), [
    (None, 0, []),
    (["--help"], 0, []),
    (["move", "--help"], 0, []),
    (["status", *NO_SERVICE], 2, ["zmq"]),
    (["move", "x=50,yaw=5", *NO_SERVICE], 2, ["zmq"]),
    (["enable", *NO_SERVICE], 2, ["zmq"]),
    (["events", *NO_SERVICE], 2, ["zmq"]),
    (["monitor", "--once", "--telemetry", NOBODY, "--timeout", "0.05"], 2, ["zmq"]),
], ids=["parser", "help", "move-help", "status", "move", "enable", "events", "monitor-once"])
def test_light_commands_load_no_heavy_module(argv: list[str] | None, status: int, allowed: list[str]) -> None:
    run = loaded_after(argv)
    assert run["status"] == status
    assert [module for module in run["heavy"] if module.split(".")[0] not in allowed] == []
    assert not any(module.startswith("zmq.auth") for module in run["heavy"])


def test_the_check_sees_a_heavy_import() -> None:
    """``serve --help`` declares its options from the service's modules: the check above
    would see them (it can fail)."""
    run = loaded_after(["serve", "--help"])
    assert run["status"] == 0
    assert "hexactl.control.realtime" in run["heavy"]
    assert "pydantic" in run["heavy"]


def deferred_command(declared: list[str]) -> argparse.ArgumentParser:
    """A ``hexactl``-like parser whose one command ``cmd`` declares ``--level`` (default 3)
    when used, noting each declaration in ``declared``."""

    def declare(parser: argparse.ArgumentParser) -> None:
        declared.append("cmd")
        parser.add_argument("--level", type=int, default=3, help="how much (default %(default)s)")

    parser = argparse.ArgumentParser(prog="hexactl")
    subparsers = parser.add_subparsers(dest="command", required=True, parser_class=DeferredParser)
    subparsers.add_parser("cmd", help="a command", declare=declare)
    subparsers.add_parser("other", help="another")
    return parser


def test_a_deferred_command_declares_its_options_once_and_only_when_named() -> None:
    declared: list[str] = []
    parser = deferred_command(declared)
    assert "a command" in parser.format_help()
    assert parser.parse_args(["other"]).command == "other"
    assert declared == []
    assert parser.parse_args(["cmd"]).level == 3
    assert parser.parse_args(["cmd", "--level", "5"]).level == 5
    assert declared == ["cmd"]


def test_a_deferred_command_shows_its_options_in_its_help(capsys: pytest.CaptureFixture[str]) -> None:
    declared: list[str] = []
    with pytest.raises(SystemExit) as stopped:
        deferred_command(declared).parse_args(["cmd", "--help"])
    assert stopped.value.code == 0
    assert "--level LEVEL  how much (default 3)" in capsys.readouterr().out
    assert declared == ["cmd"]


def test_a_deferred_command_refuses_a_bad_option_value(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        deferred_command([]).parse_args(["cmd", "--level", "high"])
    assert stopped.value.code == 2
    assert "usage: hexactl cmd [-h] [--level LEVEL]" in capsys.readouterr().err


def test_serve_help_says_what_fifo_sets(capsys: pytest.CaptureFixture[str]) -> None:
    """``--fifo``'s help, declared on use, names the priorities the service gives: the loop's
    by default, the simulator's just below, and the API process's stop path its niceness."""
    from hexactl.adapters.cli.main import main
    from hexactl.application.service import API_URGENT_NICENESS
    from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY

    with pytest.raises(SystemExit) as stopped:
        main(["serve", "--help"])
    assert stopped.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"SCHED_FIFO priority 2-99 of the loop (default {DEFAULT_FIFO_PRIORITY}: real-time is the default, " \
           "--no-realtime turns it off)" in text
    assert "PRIO-1 for the simulator's thread" in text
    assert f"the API process's threads on the way of a stop get nice {API_URGENT_NICENESS}" in text
