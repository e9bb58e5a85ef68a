"""What every sub-command shares: the --config option, the options of a client of the
service, pose arguments, error type, deferred declaration; how a campaign-driving command
(``demo``, ``campaign``) ends when stopped.

Start-up: ``hexactl`` builds the parser of every command before it runs one, so this
module and each ``*_commands`` module import only the standard library and light modules
(:mod:`~hexactl.adapters.api.protocol`, :mod:`~hexactl.kinematics.axes`) at the top; what a command needs to run (numpy, the calibration, the service) is imported
in the function that runs it, and a command whose options show defaults from such modules
declares them in a :class:`DeferredParser`. ``tests/cli/test_startup.py`` checks it.
"""

from __future__ import annotations

import argparse
import difflib
import errno
import os
import re
import sys
from collections.abc import Callable, Sequence
from math import isfinite
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

from hexactl.adapters.api.protocol import DEFAULT_TIMEOUT_S, MAX_TIMEOUT_S, check_telemetry_rate
from hexactl.adapters.files.atomic import NotARegularFile, replaceable, same_file, write_problem
from hexactl.adapters.files.config_path import CONFIG_ENVIRONMENT_VARIABLE
from hexactl.kinematics.axes import MAX_TILT_DEG, POSE_AXES, validate_pose_values
from hexactl.kinematics.plain_numbers import PLAIN_DECIMAL, PLAIN_DECIMAL_HINT

if TYPE_CHECKING:  # loaded only by the commands that use them
    from hexactl.adapters.api.client import HexactlClient, TelemetrySubscriber
    from hexactl.application.campaign.driver import CampaignError
    from hexactl.application.campaign.progress import Progress
    from hexactl.kinematics.geometry import Geometry

Connection = TypeVar("Connection", "HexactlClient", "TelemetrySubscriber")

LEG_LABELS = tuple(f"L{leg}" for leg in range(1, 7))
"""The legs' names in arguments and messages: L1 … L6."""


class CliError(Exception):
    """Bad input to a command: printed as ``hexactl CMD: error: …``, exit status 2."""


NEGATIVE_NUMBERS = re.compile(r"^-(\d|\.\d|inf|nan)[\d.,eE+-]*$|^-(inf|nan)$", re.IGNORECASE)
"""What the parsers read as a value, not an option, though it starts with ``-``: a negative
number or a comma list starting with one (``-10``, ``-1.5e3``, ``-10,0,0,0,0,0``), so that
``hexactl move -10,0,0,0,0,0`` needs no ``--``. No option of hexactl looks like one."""

DASH_HINT = "a value starting with '-' is read as an option: put it after `--`, e.g. hexactl move -- -10,0,0,0,0,0"
_MISREAD = ("unrecognized arguments", "the following arguments are required", "expected one argument",
            "expected at least one argument")


class DeferredParser(argparse.ArgumentParser):
    """The parser of ``hexactl`` and of every sub-command (its ``parser_class``): reads
    :data:`NEGATIVE_NUMBERS` as values, and adds to argparse's errors what to do: "did you
    mean" for a mistyped choice, where ``--`` goes.

    Given ``subparsers.add_parser(name, …, declare=function)``, ``function(parser)`` adds the
    command's options when the parser is first used (to parse, or to format its usage or
    help): only for the command the command line names. For a command whose options show
    defaults from modules too heavy to load for every other command (the service's, the
    calibration's)."""

    def __init__(self, *args: Any, declare: Callable[[argparse.ArgumentParser], None] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._declare: Callable[[argparse.ArgumentParser], None] | None = declare
        self._negative_number_matcher = NEGATIVE_NUMBERS  # argparse's own matcher knows single numbers only
        self._arguments: list[str] = []

    def _declared(self) -> None:
        if self._declare is not None:
            declare, self._declare = self._declare, None
            declare(self)

    def parse_known_args(self, args: Sequence[str] | None = None,
                         namespace: argparse.Namespace | None = None) -> tuple[argparse.Namespace, list[str]]:
        self._declared()
        self._arguments = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        """argparse's error (usage, message, exit status 2) with what to do about it."""
        super().error(message + "".join(f"\n  {hint}" for hint in self._hints(message)))

    def _hints(self, message: str) -> list[str]:
        hints = []
        if choice := re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)$", message):
            offered = re.findall(r"'([^']*)'", choice.group(2))
            hints += [f"did you mean {close!r}?" for close in difflib.get_close_matches(choice.group(1), offered, n=1)]
        if message.startswith(_MISREAD):
            if "--" in self._arguments and message.startswith("unrecognized arguments"):
                hints.append("options go before `--`: everything after it is read as values")
            elif any(re.match(r"-\.?\d", text) for text in self._arguments):
                hints.append(DASH_HINT)
        return hints

    def format_usage(self) -> str:
        self._declared()
        return super().format_usage()

    def format_help(self) -> str:
        self._declared()
        return super().format_help()


class VersionAction(argparse.Action):
    """``hexactl --version``: the installed package's version, looked up only when asked
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


def named_path(text: str) -> Path:
    """A file or folder named on the command line. Empty is refused: ``--config "$FILE"``
    with the variable unset would otherwise mean the default geometry (another machine's
    limits) or, as a path, the working directory."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path: name a file or folder (an unset shell variable?)")
    return Path(text)


def common_parser() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--config",
        type=named_path,
        metavar="FILE",
        help=f"geometry or calibration TOML (default: ${CONFIG_ENVIRONMENT_VARIABLE}, else ./config/platform.toml, "
             "else the repository's config/platform.toml)",
    )
    return common


def connection_parser() -> argparse.ArgumentParser:
    """The options of every client of the service: timeout and CURVE keys (see :func:`connect`)."""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--timeout", type=checked_number(_timeout_problem), default=DEFAULT_TIMEOUT_S, metavar="S",
                        help=f"seconds to wait for the service (default {DEFAULT_TIMEOUT_S:g}, at most {MAX_TIMEOUT_S:g})")
    parser.add_argument("--curve-server", type=Path, metavar="FILE", help="the service's CURVE public key (a service beyond localhost; default $HEXACTL_CURVE_SERVER, else the client file)")
    parser.add_argument("--curve-client", type=Path, metavar="FILE", help="this client's CURVE secret key (default $HEXACTL_CURVE_CLIENT, else the client file)")
    return parser


def _timeout_problem(seconds: float) -> str | None:
    if not 0 < seconds <= MAX_TIMEOUT_S:
        return f"{seconds:g} s: a client waits for the service more than 0 s and at most {MAX_TIMEOUT_S:g} s (an hour)"
    return None


def connect(kind: type[Connection], endpoint: str, arguments: argparse.Namespace, **options: Any) -> Connection:
    """A client of ``kind`` with the CURVE keys the arguments (:func:`connection_parser`)
    name; CliError for bad keys, or for an endpoint ZeroMQ refuses (the parsers and
    :func:`~hexactl.adapters.cli.endpoints.fill_endpoints` check its form before)."""
    if (arguments.curve_server is None) != (arguments.curve_client is None):
        raise CliError("give both --curve-server and --curve-client, or neither")
    import zmq  # loaded by ``kind``'s module already

    try:
        if arguments.curve_server is None:
            return kind(endpoint, **options)
        from hexactl.adapters.api.security import CurveClientKeys, SecurityError  # zmq.auth: only with keys

        try:
            return kind(endpoint, curve=CurveClientKeys(arguments.curve_server, arguments.curve_client), **options)
        except (SecurityError, OSError, ValueError) as error:  # missing or malformed key files
            raise CliError(f"CURVE keys: {error}") from None
    except zmq.ZMQError as error:
        if error.errno in (errno.EMFILE, errno.ENFILE):  # not the endpoint's fault: the form would mislead
            raise CliError(f"cannot connect to {endpoint!r}: {zmq.strerror(error.errno)}: this process (or the "
                           "system) has no file descriptor left; close what holds them, or raise the limit "
                           "(ulimit -n)") from None
        raise CliError(f"cannot connect to {endpoint!r}: {zmq.strerror(error.errno)}; {ENDPOINT_FORMS['connect']}") from None


ENDPOINT_FORMS = {
    "connect": "expected tcp://HOST:PORT with a port 1-65535 (e.g. tcp://127.0.0.1:5555) or ipc://PATH",
    "bind": "expected tcp://HOST:PORT with a port 1-65535, or * for a free one (e.g. tcp://127.0.0.1:5555, "
            "tcp://127.0.0.1:*), or ipc://PATH",
}
"""What an endpoint of a client (``connect``) or of ``hexactl serve`` (``bind``) looks like."""


def endpoint_problem(text: str, use: str = "connect") -> str | None:
    """What is wrong with ``text`` as a ZeroMQ endpoint to ``use`` (``connect`` or
    ``bind``), with the form expected; None if nothing. Only the forms hexactl's services
    speak: TCP (a host name, an address, ``[IPv6]``, an interface; for a client also
    ``SOURCE;DESTINATION``) and ``ipc://`` (a local socket file). Checked here, before
    ZeroMQ, whose ``Invalid argument`` names neither the option nor the form, and whose
    bind takes a port above 65535 modulo 65536."""
    expected = ENDPOINT_FORMS[use]
    scheme, separator, address = text.partition("://")
    if not separator:
        return f"{text!r} is not an endpoint: {expected}"
    if scheme == "ipc":
        return None if address.strip() else f"{text!r} names no socket file: {expected}"
    if scheme != "tcp":
        return f"{text!r}: {scheme}:// is not a transport hexactl serves: {expected}"
    destination = address.rpartition(";")[2] if use == "connect" else address
    host, colon, port = destination.rpartition(":")
    if not colon or not host.strip("[]") or any(character.isspace() for character in host):
        return f"{text!r} names no host and port: {expected}"
    if use == "bind" and port == "*":
        return None
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        return f"{text!r}: {port!r} is not a port 1-65535: {expected}"
    return None


def client_endpoint(text: str) -> str:
    """An argparse ``type``: an endpoint to connect to (``--api``, ``--telemetry``)."""
    if problem := endpoint_problem(text, "connect"):
        raise argparse.ArgumentTypeError(problem)
    return text


def bind_endpoint(text: str) -> str:
    """An argparse ``type``: an endpoint ``hexactl serve`` binds (``--api``, ``--telemetry``, ``--stream``)."""
    if problem := endpoint_problem(text, "bind"):
        raise argparse.ArgumentTypeError(problem)
    return text


def load_config(arguments: argparse.Namespace) -> Geometry:
    """The geometry named by --config, or the default one; CliError if it is refused."""
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.kinematics.geometry import GeometryError

    try:
        return load_geometry(config_input(arguments))
    except GeometryError as error:
        raise CliError(str(error)) from None


def check_output(output: str | None, force: bool, *inputs: str | Path | None) -> None:
    """Before any work: :class:`CliError` if ``output`` is one of the command's ``inputs``
    (never written over, even with --force: a measurement file can be hours of measuring),
    exists and ``force`` is not given, or is not a file (a device, a pipe: never replaced)."""
    if output is None:
        return
    for given in inputs:
        if given is not None and same_file(output, given):
            raise CliError(f"{output} is this command's input {given}: an input is never written over, even with "
                           "--force; choose another output")
    if Path(output).is_dir():
        raise CliError(f"{output} is a folder: name the file to write")
    if Path(output).exists() and not force:
        raise CliError(f"{output} exists; refusing to overwrite it (use --force)")
    try:
        replaceable(Path(output))
    except NotARegularFile as error:
        raise CliError(str(error)) from None
    check_writable(Path(output))


def check_writable(path: Path, *, folder: bool = False) -> None:
    """Before any work: :class:`CliError` if the file (or, with ``folder``, the folder)
    ``path`` could not be written because a file stands where a folder must be, or because
    of permissions. Missing folders are fine: writing makes them."""
    existing = path if folder else path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise CliError(f"cannot write {path}: {existing} is a file, not a folder; choose another place")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise CliError(f"cannot write {path}: no permission to write into {existing}; choose another place")
    import tempfile  # only where a command writes: the start-up of the others stays light

    try:  # a read-only file system, or one like /proc, passes os.access (as root, always): try it
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as error:
        raise write_failed(path, error) from None


def write_failed(path: str | os.PathLike[str], error: OSError) -> CliError:
    """The :class:`CliError` for ``error`` while writing ``path``: the file, why, and what
    to do (a full disk's ``[Errno 28]`` named neither the file nor that). An error of
    hexactl's own (a file it refuses to replace: it says to use --force) is passed on."""
    if error.strerror is None:
        return CliError(str(error))
    return CliError(f"cannot write {path}: {write_problem(error)}, or choose another place")


def config_input(arguments: argparse.Namespace) -> Path:
    """The geometry file the command reads (--config, else the default one)."""
    from hexactl.adapters.files.config_path import default_config_path

    return Path(arguments.config) if arguments.config else default_config_path()


def check_campaign_arguments(arguments: argparse.Namespace) -> None:
    """``--per-leg`` and ``--envelope`` of a campaign-driving command (``demo``, ``campaign``).

    :raises CliError: naming the option and what it must be
    """
    from hexactl.calibration.results import MIN_POSTURES
    from hexactl.kinematics.inverse import LEG_COUNT

    fewest = -(-MIN_POSTURES // LEG_COUNT)
    if arguments.per_leg < fewest:  # before anything moves: else hours of measuring that cannot be used
        raise CliError(f"--per-leg {arguments.per_leg}: {max(arguments.per_leg, 0) * LEG_COUNT} postures, and the "
                       f"identification needs at least {MIN_POSTURES}: give --per-leg {fewest} or more (the default, "
                       "20, for an accurate calibration)")
    if not 0 < arguments.envelope <= 1:
        raise CliError(f"--envelope {arguments.envelope}: a fraction in (0, 1]")


def campaign_stopped(command: str, stopped_by: CampaignError | KeyboardInterrupt, directory: Path, progress: Progress) -> int:
    """The exit status of ``hexactl COMMAND`` driving a campaign in ``directory`` when
    ``stopped_by`` ended it: the progress line finished, then the reason on stderr. A
    :class:`~hexactl.application.campaign.driver.CampaignError` (it cannot go on): 1. Ctrl-C:
    how to resume (everything measured is saved): 130."""
    progress.finish()
    if isinstance(stopped_by, KeyboardInterrupt):
        print(f"hexactl {command}: interrupted; what was measured is saved in {directory}: run the same command to "
              "resume", file=sys.stderr)
        return 130
    print(f"hexactl {command}: {stopped_by}", file=sys.stderr)
    return 1


_KEYED = re.compile(r"^\s*(x|y|z|roll|pitch|yaw)\s*=\s*(\S+)\s*$")

POSE_FORMS = "six numbers X,Y,Z,ROLL,PITCH,YAW (e.g. 10,0,50,0,0,5) or axis=value pairs, the others 0 (e.g. x=10,z=50,yaw=5)"


def parse_pose_argument(text: str, what: str = "pose") -> list[float]:
    """A pose typed on the command line, mm and deg (relative to the zero posture, or in the
    frame the command names), or six values of another ``what`` per axis (a velocity).

    Either six comma-separated numbers ``X,Y,Z,ROLL,PITCH,YAW`` or ``axis=value`` pairs
    separated by commas, missing axes 0: ``x=600``, ``pitch=-20,yaw=5``; not both in one
    argument, and each axis once (as the API, which refuses a repeated key). No field empty:
    ``5,,0,0,0,0`` is a value left out, not five numbers.
    """
    if not text.strip():
        raise CliError(f"{what} {text!r}: empty: give {POSE_FORMS}")
    parts = text.split(",")
    if (empty := next((i for i, part in enumerate(parts, start=1) if not part.strip()), None)) is not None:
        raise CliError(f"{what} {text!r}: field {empty} of {len(parts)} is empty (two commas in a row, or one at an "
                       f"end): give {POSE_FORMS}")
    keyed = [part for part in parts if "=" in part]
    if keyed and len(keyed) < len(parts):
        plain = next(part.strip() for part in parts if "=" not in part)
        raise CliError(f"{what} {text!r}: axis=value pairs and plain numbers cannot be mixed ({keyed[0].strip()!r} "
                       f"and {plain!r}): give {POSE_FORMS}")
    if keyed:
        pose = _keyed_values(what, text, parts, 0.0)
    elif len(parts) == 1 and _all_numbers(text.split()):  # `move 0 0 50 0 0 0`, or "0 0 50 0 0 0"
        raise CliError(f"{what} {text!r}: one value where six are needed: give {POSE_FORMS}, as one argument with "
                       "commas between the numbers (not spaces)")
    else:
        pose = [_number(part, text) for part in parts]
    problem = validate_pose_values(pose)
    if problem:
        raise CliError(f"{what} {text!r}: {problem.replace('pose', what)}")
    return pose


NO_BOUND = "none"
"""Typed for a soft bound (``x=none``, ``--max-tilt none``): remove it."""

_UNNAMED = object()


def parse_bound_changes(text: str) -> dict[str, float | None]:
    """Soft bounds to change, typed on the command line: ``axis=value`` pairs (mm, deg), each
    axis once, :data:`NO_BOUND` removing that axis's bound: ``x=-50,z=none``. The axes not
    named are not in the result (they keep theirs)."""
    values = _keyed_values("bounds", text, [part for part in text.split(",") if part.strip()], _UNNAMED,
                           lambda value, context: None if value.lower() == NO_BOUND else _number(value, context))
    changes = {axis: value for axis, value in zip(POSE_AXES, values) if value is not _UNNAMED}
    if any(bound is not None and not isfinite(bound) for bound in changes.values()):
        raise CliError(f"bounds {text!r}: every value must be a finite number, or {NO_BOUND} to remove that bound")
    return changes


def _keyed_values(what: str, text: str, parts: list[str], missing: Any,
                  number: Callable[[str, str], Any] | None = None) -> list[Any]:
    """The values of ``axis=value`` ``parts`` in axis order, ``missing`` for an axis not
    named; ``number`` reads a value (default: a number)."""
    number = number or _number
    values: list[Any] = [missing] * 6
    given: dict[str, str] = {}
    for part in parts:
        match = _KEYED.match(part)
        if not match:
            raise CliError(f"{what} {text!r}: {part.strip()!r} is not axis=value with axis one of {', '.join(POSE_AXES)}"
                           f" (e.g. x=10,yaw=5)")
        axis = match.group(1)
        if axis in given:
            raise CliError(f"{what} {text!r}: axis {axis} is given twice ({given[axis]!r} and {part.strip()!r}): give "
                           "each axis once")
        given[axis] = part.strip()
        values[POSE_AXES.index(axis)] = number(match.group(2), text)
    return values


def pose_argument(text: str) -> list[float]:
    """:func:`parse_pose_argument` as an argparse ``type``: its error becomes argparse's."""
    return _argparse_type(parse_pose_argument, text)


def velocity_argument(text: str) -> list[float]:
    """Six velocities typed as a pose is (:func:`parse_pose_argument`), mm/s and deg/s."""
    return _argparse_type(lambda typed: parse_pose_argument(typed, "velocity"), text)


def bound_changes_argument(text: str) -> dict[str, float | None]:
    """:func:`parse_bound_changes` as an argparse ``type``."""
    return _argparse_type(parse_bound_changes, text)


class MergedBounds(argparse.Action):
    """An option of :func:`bound_changes_argument` pairs given more than once: the pairs of
    all of them (the last alone was kept, and a bound typed before it dropped unseen), an
    axis in one of them only, as within one."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        merged = dict(getattr(namespace, self.dest) or {})
        if repeated := [axis for axis in values if axis in merged]:
            parser.error(f"argument {option_string}: {', '.join(repeated)} given in two {option_string} options: "
                         "give each axis once (the options' pairs add up)")
        setattr(namespace, self.dest, {**merged, **values})


def tilt_bound_argument(text: str) -> float | str:
    """An argparse ``type``: a tilt bound in (0, :data:`~hexactl.kinematics.axes.MAX_TILT_DEG`]
    deg, or :data:`NO_BOUND`."""
    return NO_BOUND if text.strip().lower() == NO_BOUND else positive_up_to(MAX_TILT_DEG, "deg")(text)


def _argparse_type(parse: Callable[[str], Any], text: str) -> Any:
    try:
        return parse(text)
    except CliError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _float_argument(text: str) -> float:
    """``text`` as a float, for an argparse ``type``; ArgumentTypeError if it is none."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if problem := not_plainly_written(text, value):
        raise argparse.ArgumentTypeError(problem)
    return value


def not_plainly_written(text: str, value: float) -> str | None:
    """Why ``text``, which Python reads as the finite ``value``, is no number an operator
    means (:mod:`hexactl.kinematics.plain_numbers`); None when it is plain decimal. Found
    from outside: ``x=1_0``, a typo for 1.0, was read as 10 mm. Non-finite values are
    left to the caller, whose message says what range it takes."""
    if isfinite(value) and not PLAIN_DECIMAL.fullmatch(text.strip()):
        return f"{text.strip()!r} is not a plain decimal number: {PLAIN_DECIMAL_HINT}"
    return None


def positive_float(text: str) -> float:
    """An argparse ``type``: a positive finite number."""
    value = _float_argument(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive finite number")
    return value


def finite_float(text: str) -> float:
    """An argparse ``type``: a finite number (whose range the command checks once it knows it)."""
    value = _float_argument(text)
    if not isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def positive_up_to(high: float, unit: str) -> Callable[[str], float]:
    """An argparse ``type``: a number in (0, ``high``] ``unit``, ``high`` the bound the
    service or a model states (taken from there)."""

    def parse(text: str) -> float:
        value = _float_argument(text)
        if not 0 < value <= high:
            raise argparse.ArgumentTypeError(f"{text!r} must be more than 0 and at most {high:g} {unit}")
        return value

    return parse


def checked_number(problem_of: Callable[[float], str | None]) -> Callable[[str], float]:
    """An argparse ``type``: a number that ``problem_of``, the rule of the module that uses it
    (e.g. :func:`~hexactl.kinematics.geometry.noise_sigma_problem`), finds nothing wrong with."""

    def parse(text: str) -> float:
        value = _float_argument(text)
        if not isfinite(value):  # said as typed: the rule's own words would say "inf s"
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if problem := problem_of(value):
            raise argparse.ArgumentTypeError(problem)
        return value

    return parse


def _whole_number(text: str) -> int:
    try:
        whole = int(text)
    except ValueError:
        pass
    else:
        if problem := not_plainly_written(text, whole):
            raise argparse.ArgumentTypeError(problem)
        return whole
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if value.is_integer() and abs(value) < 1e18:  # 3.0 is whole, but not written as one
        raise argparse.ArgumentTypeError(f"{text!r} is not written as a whole number: write {value:.0f}")
    raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def whole_number(text: str) -> int:
    """An argparse ``type``: a whole number, plainly written (Python's ``int`` takes ``0_3``
    and other scripts' digits: ``leg-lock ３`` locked leg 3, found from outside); its range
    is the option's ``choices`` or the command's."""
    return _whole_number(text)


def positive_int(text: str) -> int:
    """An argparse ``type``: a whole number from 1."""
    if (value := _whole_number(text)) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def non_negative_int(text: str) -> int:
    """An argparse ``type``: a whole number from 0 (a seed, a count that may be none)."""
    if (value := _whole_number(text)) < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be 0 or more")
    return value


def whole_number_in(low: int, high: int) -> Callable[[str], int]:
    """An argparse ``type``: a whole number from ``low`` to ``high``."""

    def parse(text: str) -> int:
        beyond = argparse.ArgumentTypeError(f"{text!r} is not a whole number from {low} to {high}")
        try:
            value = _whole_number(text)
        except argparse.ArgumentTypeError:
            try:  # 1e9: "write 1000000000" would only lead to this refusal next
                out_of_range = isfinite(number := float(text)) and not low <= number <= high
            except ValueError:
                out_of_range = False
            if out_of_range:
                raise beyond from None
            raise
        if not low <= value <= high:
            raise beyond
        return value

    return parse


def telemetry_rate(text: str) -> float:
    """An argparse ``type``: a telemetry rate, records per second, that the publisher can keep."""
    try:
        return check_telemetry_rate(positive_float(text))
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def fifo_priority(lowest: int) -> Callable[[str], int]:
    """An argparse ``type``: a SCHED_FIFO priority from ``lowest`` to 99."""

    def parse(text: str) -> int:
        if not lowest <= (value := _whole_number(text)) <= 99:
            raise argparse.ArgumentTypeError(f"{value} is not a SCHED_FIFO priority from {lowest} to 99")
        return value

    return parse


def fraction(text: str) -> float:
    """An argparse ``type``: a number in (0, 1] (``move --speed``)."""
    value = _float_argument(text)
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be a fraction in (0, 1] of the velocity limits, e.g. 0.5")
    return value


def parse_numbers(values: list[str], labels: tuple[str, ...]) -> list[float]:
    """Finite numbers given as separate arguments, one per label (e.g. ``ik X Y Z ROLL PITCH YAW``).

    :raises CliError: a value is not a finite number, or there is not one per label
    """
    if len(values) != len(labels):
        raise CliError(f"give {len(labels)} numbers ({','.join(labels)}), not {len(values)}")
    numbers = []
    for label, value in zip(labels, values, strict=True):
        number = _number(value, label)
        if not isfinite(number):
            raise CliError(f"{label}: {value!r} is not a finite number")
        numbers.append(number)
    return numbers


def _all_numbers(words: list[str]) -> bool:
    try:
        [float(word) for word in words]
    except ValueError:
        return False
    return True


def _number(text: str, context: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise CliError(f"{context}: {text.strip()!r} is not a number") from None
    if problem := not_plainly_written(text, value):
        raise CliError(f"{context}: {problem}")
    return value
