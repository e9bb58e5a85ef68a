# PYTHON_ARGCOMPLETE_OK  (argcomplete's marker: `eval "$(register-python-argcomplete hexactl)"` completes hexactl)
"""The ``hexactl`` command: one entry point, one module per group of sub-commands.

Each command module exposes ``register(subparsers, common)`` that adds its sub-commands;
``common`` is the parent parser with the options every sub-command takes (``--config``).
A command returns its exit status: 0 success, 1 the answer is "no" (unreachable pose,
non-converged solution), 2 bad input (arguments, files).

Every command's parser is built before one runs, so the command modules import only
light modules at the top and defer the rest (:mod:`hexactl.adapters.cli.common`): ``--help``
and the client commands (``status``, ``move``, …) start without numpy, scipy or pydantic.

Ctrl-C anywhere in :func:`main`, from the import of the command modules to the end of the
command, ends it with one line (``hexactl COMMAND: interrupted``) and status 130, never
a traceback: this module imports only built-in modules at the top, and the command
modules inside :func:`main` (through :func:`build_parser`). Only the interpreter's own
start-up, before this module runs, is Python's.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # nothing but the built-in modules before main() runs: a Ctrl-C there is not caught
    import argparse
    from collections.abc import Sequence
    from types import FrameType, ModuleType

EXIT_BROKEN_PIPE = 141
"""The shell's status for a command killed by SIGPIPE (128 + 13), e.g. ``hexactl … | head``."""

EXIT_INTERRUPTED = 130
"""The shell's status for a command ended by Ctrl-C (128 + SIGINT's 2)."""


def command_modules() -> tuple[ModuleType, ...]:
    """The modules of the sub-commands, imported when first asked for (by :func:`main`,
    where a Ctrl-C during their import is caught)."""
    from hexactl.adapters.cli import (
        calibration_commands,
        cue_commands,
        dashboard_commands,
        demo_commands,
        event_commands,
        jog_commands,
        kinematics_commands,
        monitor,
        recording_commands,
        service_commands,
        sim_commands,
        wave_commands,
    )

    return (kinematics_commands, sim_commands, service_commands, jog_commands, recording_commands, wave_commands,
            monitor, event_commands, dashboard_commands, calibration_commands, demo_commands, cue_commands)


def build_parser() -> argparse.ArgumentParser:
    from hexactl.adapters.cli.common import DeferredParser, VersionAction, common_parser

    parser = DeferredParser(
        prog="hexactl",
        description="Controller and calibration toolkit for six-actuator parallel platforms.",
        epilog="Shell completion: eval \"$(register-python-argcomplete hexactl)\".",
    )
    parser.add_argument("--version", action=VersionAction)
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=DeferredParser)
    common = common_parser()
    for module in command_modules():
        module.register(subparsers, common)
    parser.command_names = frozenset(subparsers.choices)  # type: ignore[attr-defined]
    return parser


MOTION_GOES_ON = " (a motion the service accepted goes on: `hexactl stop` halts it)"
"""Said when Ctrl-C ends a command that starts a motion: only the command ends, not the motion."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``hexactl ARGV`` (None: the command line of this process); its exit status.

    Called with None it is the program: Ctrl-C once the command is over (while the
    interpreter exits) ends it quietly too."""
    command: list[str] = []  # the sub-command once known, for the messages
    try:
        return _run(argv, command)
    except KeyboardInterrupt:
        if argv is None:  # a second Ctrl-C while this one is reported: nothing left to interrupt
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        # CPython (3.11) remembers a KeyboardInterrupt that went through an exec() of a string
        # (dataclasses, namedtuple and pydantic build their code so, while the commands import)
        # and, under `python3 -m`, kills the process with SIGINT at exit though it was caught
        # here: an exec() of its own forgets it, so that the status is 130 whatever was importing.
        exec("")  # noqa: S102
        print(f"hexactl{''.join(' ' + name for name in command)}: interrupted"
              + (MOTION_GOES_ON if command[:1] in (["move"], ["play"], ["wave"]) else ""), file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        if argv is None:
            _quiet_interrupt_from_now_on(command)


def _run(argv: Sequence[str] | None, command: list[str]) -> int:
    words = [word for word in (sys.argv[1:] if argv is None else argv) if not word.startswith("-")]
    command[:] = words[:1]  # the command named, for a Ctrl-C while it loads (its parse may load the service)
    from hexactl.adapters.cli.common import CliError
    from hexactl.adapters.cli.endpoints import fill_endpoints

    parser = build_parser()
    command[:] = [name for name in command if name in parser.command_names]
    if "_ARGCOMPLETE" in os.environ:  # the shell asks for completions: only then load argcomplete
        import argcomplete

        argcomplete.autocomplete(parser)
    arguments = parser.parse_args(argv)
    command[:] = [arguments.command]
    try:
        fill_endpoints(arguments)
        return int(arguments.run(arguments))
    except CliError as error:
        print(f"hexactl {arguments.command}: error: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (`| head`): stop quietly, as a killed command would
        # Whatever is still buffered would raise again when the interpreter flushes stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


def _quiet_interrupt_from_now_on(command: list[str]) -> None:
    """The command is over and the interpreter about to exit (its exit handlers may still
    wait, e.g. for child processes): Ctrl-C from now on ends the process at once with one
    line and status 130, not with a traceback from wherever the exit had got to. Only if
    SIGINT still has Python's own handler (not ignored, not a command's)."""
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return
    line = f"hexactl{''.join(' ' + name for name in command)}: interrupted\n".encode()

    def leave(signum: int, frame: FrameType | None) -> None:
        try:
            sys.stdout.flush()
        except Exception:  # noqa: BLE001 - a broken pipe, or interrupted mid-write: what is left is lost
            pass
        os.write(sys.stderr.fileno(), line)
        os._exit(EXIT_INTERRUPTED)

    signal.signal(signal.SIGINT, leave)


if __name__ == "__main__":
    sys.exit(main())
