"""Where the client commands find the service, set once: each of the command endpoint,
the telemetry endpoint and the CURVE key files comes from, first found,

1. the command line (``--api``, ``--telemetry``, ``--curve-server``/``--curve-client``),
2. the environment (``HEXACTL_API``, ``HEXACTL_TELEMETRY``, ``HEXACTL_CURVE_SERVER``,
   ``HEXACTL_CURVE_CLIENT``),
3. the client file: ``$HEXACTL_CLIENT_CONFIG``, else ``$XDG_CONFIG_HOME/hexactl/client.toml``
   (``~/.config/hexactl/client.toml``), with the keys ``api``, ``telemetry``,
   ``curve_server``, ``curve_client``,
4. the defaults (``tcp://127.0.0.1:5555`` and ``:5556``, no CURVE).

Only the clients: ``hexactl serve`` binds what its own options say. ``hexactl status``
shows the endpoint it talked to and where that came from.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from hexactl.adapters.api.protocol import DEFAULT_API_ENDPOINT, DEFAULT_TELEMETRY_ENDPOINT
from hexactl.adapters.cli.common import CliError, endpoint_problem

CLIENT_CONFIG_VARIABLE = "HEXACTL_CLIENT_CONFIG"

SETTINGS = {  # argument name → (environment variable, client file key, default)
    "api": ("HEXACTL_API", "api", DEFAULT_API_ENDPOINT),
    "telemetry": ("HEXACTL_TELEMETRY", "telemetry", DEFAULT_TELEMETRY_ENDPOINT),
    "curve_server": ("HEXACTL_CURVE_SERVER", "curve_server", None),
    "curve_client": ("HEXACTL_CURVE_CLIENT", "curve_client", None),
}
_PATHS = ("curve_server", "curve_client")


_DEFAULT_CLIENT_FILE = "$XDG_CONFIG_HOME/hexactl/client.toml (~/.config/hexactl/client.toml)"


def client_config_path() -> Path:
    """The client file: ``$HEXACTL_CLIENT_CONFIG``, else ``$XDG_CONFIG_HOME/hexactl/client.toml``."""
    if named := os.environ.get(CLIENT_CONFIG_VARIABLE):
        return Path(named)
    home = os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config"
    return Path(home) / "hexactl" / "client.toml"


def fill_endpoints(arguments: argparse.Namespace) -> None:
    """Give every setting of :data:`SETTINGS` the command declares and the command line left
    unset (None) its value from the environment, the client file or the default, and note
    where each came from in ``arguments.origins`` (``--api``, ``HEXACTL_API``, the file,
    ``default``). The CURVE keys come from one place, as a pair.

    :raises CliError: the client file is not valid TOML, has unknown keys or non-string values;
        an endpoint from the environment or the file is not one (the command line's are
        checked by their parsers: :func:`~hexactl.adapters.cli.common.client_endpoint`)
    """
    declared = [name for name in SETTINGS if hasattr(arguments, name)]
    if not declared:
        return
    origins: dict[str, str] = {}
    unset = []
    for name in declared:
        if getattr(arguments, name) is None:
            unset.append(name)
        else:
            origins[name] = "--" + name.replace("_", "-")
    if set(_PATHS) <= set(declared) and any(getattr(arguments, name) is not None for name in _PATHS):
        unset = [name for name in unset if name not in _PATHS]  # a pair: half on the command line is connect()'s error
    file_values: dict[str, Any] | None = None
    for name in unset:
        variable, key, default = SETTINGS[name]
        value, origin = os.environ.get(variable) or None, variable
        if value is None:
            if file_values is None:
                file_values = _read_client_file()
            value, origin = file_values.get(key), str(client_config_path())
        if value is None:
            value, origin = default, "default"
        elif name not in _PATHS and (problem := endpoint_problem(value)):  # the command line's: argparse checked
            raise CliError(f"{origin if origin == variable else f'{origin}: {key}'}: {problem}")
        setattr(arguments, name, Path(value) if name in _PATHS and value is not None else value)
        origins[name] = origin
    arguments.origins = origins


def _read_client_file() -> dict[str, Any]:
    """The client file's settings: none from a default file not there; a file named by
    :data:`CLIENT_CONFIG_VARIABLE` must be there and name one (else the commands would go,
    unsaid, to the default endpoint: another machine's service, perhaps)."""
    path = client_config_path()
    named = bool(os.environ.get(CLIENT_CONFIG_VARIABLE))
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        if named:
            raise CliError(f"{CLIENT_CONFIG_VARIABLE}={path}: no such file: check the name, or unset "
                           f"{CLIENT_CONFIG_VARIABLE} to use {_DEFAULT_CLIENT_FILE}") from None
        return {}
    except OSError as error:
        from hexactl.adapters.files.text import read_problem

        raise CliError(f"{path}: the client file: {read_problem(error)}; fix it or set {CLIENT_CONFIG_VARIABLE}") \
            from None
    import tomllib  # only when there is a file

    from hexactl.adapters.files.text import TextFileError, decode_text

    try:
        text = decode_text(data, f"{path} (the client file)")
    except TextFileError as error:
        raise CliError(str(error)) from None

    try:
        values = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise CliError(f"{path}: not valid TOML: {error}") from None
    known = {key for _, key, _ in SETTINGS.values()}
    if unknown := sorted(set(values) - known):
        raise CliError(f"{path}: unknown key {', '.join(unknown)}; the client file knows {', '.join(sorted(known))}")
    if wrong := sorted(key for key, value in values.items() if not isinstance(value, str)):
        raise CliError(f"{path}: {', '.join(wrong)}: must be a string, e.g. api = \"tcp://10.0.0.2:5555\"")
    if named and not values:
        raise CliError(f"{CLIENT_CONFIG_VARIABLE}={path}: the file names no setting; give at least one of "
                       f"{', '.join(sorted(known))}, e.g. api = \"tcp://10.0.0.2:5555\"")
    return values
