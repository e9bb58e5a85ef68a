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
import sys
from collections.abc import Sequence

from hexactl.adapters.cli import calibration_commands, demo_commands, kinematics_commands, service_commands, sim_commands
from hexactl.adapters.cli.common import CliError, DeferredParser, common_parser

COMMAND_MODULES = (kinematics_commands, sim_commands, service_commands, calibration_commands, demo_commands)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hexactl",
        description="Controller and calibration toolkit for six-actuator parallel platforms.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=DeferredParser)
    common = common_parser()
    for module in COMMAND_MODULES:
        module.register(subparsers, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    arguments = parser.parse_args(argv)
    try:
        return int(arguments.run(arguments))
    except CliError as error:
        print(f"hexactl {arguments.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
