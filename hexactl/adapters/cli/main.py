# PYTHON_ARGCOMPLETE_OK  (argcomplete's marker: `eval "$(register-python-argcomplete hexactl)"` completes hexactl)
"""The ``hexactl`` command: one entry point, one module per group of sub-commands.

Each command module exposes ``register(subparsers, common)`` that adds its sub-commands;
``common`` is the parent parser with the options every sub-command takes (``--config``).
A command returns its exit status: 0 success, 1 the answer is "no" (unreachable pose,
non-converged solution), 2 bad input (arguments, files).

Every command's parser is built before one runs, so the command modules import only
light modules at the top and defer the rest (:mod:`hexactl.adapters.cli.common`): ``--help``
and the client commands (``status``, ``move``, …) start without numpy, scipy or pydantic.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from hexactl.adapters.cli import (
    calibration_commands,
    cue_commands,
    dashboard_commands,
    demo_commands,
    jog_commands,
    kinematics_commands,
    monitor,
    recording_commands,
    service_commands,
    sim_commands,
    wave_commands,
)
from hexactl.adapters.cli.common import CliError, DeferredParser, common_parser
from hexactl.adapters.cli.endpoints import fill_endpoints

COMMAND_MODULES = (kinematics_commands, sim_commands, service_commands, jog_commands, recording_commands, wave_commands,
                   monitor, dashboard_commands, calibration_commands, demo_commands, cue_commands)

EXIT_BROKEN_PIPE = 141
"""The shell's status for a command killed by SIGPIPE (128 + 13), e.g. ``hexactl … | head``."""


class _VersionAction(argparse.Action):
    """``--version``: the installed package's version, looked up only when asked
    (importlib.metadata is too slow to load for every command)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="print the version and exit")

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        from importlib.metadata import PackageNotFoundError, version

        try:
            found = version("hexactl")
        except PackageNotFoundError:
            found = "unknown (not installed: python3 -m pip install -e .)"
        print(f"hexactl {found}")  # to stdout, as argparse's own version action
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = DeferredParser(
        prog="hexactl",
        description="Controller and calibration toolkit for six-actuator parallel platforms.",
        epilog="Shell completion: eval \"$(register-python-argcomplete hexactl)\".",
    )
    parser.add_argument("--version", action=_VersionAction)
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=DeferredParser)
    common = common_parser()
    for module in COMMAND_MODULES:
        module.register(subparsers, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    if "_ARGCOMPLETE" in os.environ:  # the shell asks for completions: only then load argcomplete
        import argcomplete

        argcomplete.autocomplete(parser)
    arguments = parser.parse_args(argv)
    try:
        fill_endpoints(arguments)
        return int(arguments.run(arguments))
    except CliError as error:
        print(f"hexactl {arguments.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader went away (`| head`): stop quietly, as a killed command would
        # Whatever is still buffered would raise again when the interpreter flushes stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
