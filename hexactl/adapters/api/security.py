"""Who may connect: local endpoints are open, anything else needs CURVE.

The API and telemetry sockets bind to the loopback interface by default, where any
local user may connect (as to the CLI). Binding anywhere else exposes the actuators
to the network, so the service refuses to start without CURVE encryption and
authentication: a server secret key file and a directory of the client public keys
allowed in (ZeroMQ certificate files, made by :func:`create_keys`).
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import zmq
import zmq.auth
from zmq.utils import z85

from hexactl.adapters.api.protocol import is_local_endpoint


class SecurityError(Exception):
    """The endpoints and keys given are not a safe configuration; the message says why."""


@dataclass(frozen=True, slots=True)
class CurveServerKeys:
    """``secret_key_file``: the server's certificate with its secret key;
    ``clients_dir``: the public certificates of the clients allowed in."""

    secret_key_file: Path
    clients_dir: Path


@dataclass(frozen=True, slots=True)
class CurveClientKeys:
    """``server_key_file``: the server's public certificate; ``secret_key_file``: this
    client's certificate with its secret key."""

    server_key_file: Path
    secret_key_file: Path


def check_endpoints(endpoints: list[str], keys: CurveServerKeys | None) -> None:
    """Refuse (SecurityError) to bind a non-local endpoint without CURVE keys, or with
    key files that are missing."""
    exposed = [endpoint for endpoint in endpoints if not is_local_endpoint(endpoint)]
    if keys is None:
        if exposed:
            raise SecurityError(
                f"refusing to bind {', '.join(exposed)} without CURVE: a non-loopback endpoint exposes the "
                "actuators to the network. Give --curve-secret SERVER.key_secret and --curve-clients DIR "
                "(make them with `hexactl keys --out DIR`), or bind to tcp://127.0.0.1"
            )
        return
    if not keys.secret_key_file.is_file():
        raise SecurityError(f"CURVE server secret key file {keys.secret_key_file} does not exist")
    client_keys(keys.clients_dir)


def client_keys(clients_dir: Path) -> list[str]:
    """The names of the client keys in ``clients_dir`` (its ``*.key`` files, as ZeroMQ's
    authenticator reads them).

    :raises SecurityError: it is not a folder; a ``*.key`` there is not a public key (the
        authenticator then loads none: every client would be locked out while the service
        said CURVE was on); or it holds none (no client could connect)
    """
    if clients_dir.is_file():
        raise SecurityError(f"CURVE clients directory {clients_dir} is a file: name the folder of the clients' public "
                            "keys (*.key; `hexactl keys --out DIR` makes DIR/clients)")
    if not clients_dir.is_dir():
        raise SecurityError(f"CURVE clients directory {clients_dir} does not exist")
    names, problems = [], []
    for path in sorted(clients_dir.glob("*.key")):
        try:
            public, _ = zmq.auth.load_certificate(path)
        except (OSError, ValueError) as error:
            problems.append(f"{path.name} ({error})")
            continue
        if public:
            names.append(path.stem)
        else:
            problems.append(f"{path.name} (no public key)")
    if problems:
        raise SecurityError(f"CURVE clients directory {clients_dir}: {', '.join(problems)} is not a client's public "
                            "key, and ZeroMQ would then let no client in: remove it, or put there the .key file "
                            "`hexactl keys` made")
    if not names:
        raise SecurityError(f"CURVE clients directory {clients_dir} holds no client key (*.key): no client could "
                            "connect; copy there each client's .key file (`hexactl keys --out DIR --name NAME`)")
    return names


def load_server_keys(keys: CurveServerKeys) -> tuple[bytes, bytes]:
    """The server's (public, secret) key pair from ``keys.secret_key_file``.

    :raises SecurityError: if the file holds no secret key
    :raises OSError, ValueError: if it cannot be read or is not a key file
    """
    public, secret = zmq.auth.load_certificate(keys.secret_key_file)
    if secret is None:
        raise SecurityError(f"{keys.secret_key_file} holds no secret key (use the .key_secret file)")
    return public, secret


class CurveServer:
    """CURVE on the service's sockets, with ZeroMQ's authenticator thread checking
    every client's public key against :attr:`CurveServerKeys.clients_dir`. A connection's
    ``User-Id`` property names its key (:func:`key_name`): who sent a command, for people."""

    def __init__(self, context: zmq.Context, keys: CurveServerKeys) -> None:
        from zmq.auth.thread import ThreadAuthenticator  # loads asyncio: only a server needs it, not every client

        self._public, self._secret = load_server_keys(keys)
        self._authenticator = ThreadAuthenticator(context)
        self._authenticator.start()
        self._authenticator.configure_curve(domain="*", location=str(keys.clients_dir))
        # The authenticator names a connection's user by this method (by default the key's
        # z85 text, which no one reads); an instance attribute replaces it.
        self._authenticator.curve_user_id = functools.partial(key_name, keys.clients_dir)  # type: ignore[method-assign]

    def secure(self, socket: zmq.Socket) -> None:
        """Make ``socket`` (before it binds) a CURVE server."""
        socket.curve_secretkey = self._secret
        socket.curve_publickey = self._public
        socket.curve_server = True

    def close(self) -> None:
        self._authenticator.stop()


def key_name(clients_dir: Path, public_key: bytes) -> str:
    """The name of the client certificate in ``clients_dir`` that holds ``public_key``
    (32 bytes): its file's stem (``alice`` for ``alice.key``), or the key's z85 text when
    no file there holds it now."""
    text = z85.encode(public_key)
    for path in sorted(clients_dir.glob("*.key")):
        try:
            public, _ = zmq.auth.load_certificate(path)
        except (OSError, ValueError):  # being written, or not a certificate: not this key
            continue
        if public == text:
            return path.stem
    return text.decode("ascii")


def secure_client(socket: zmq.Socket, keys: CurveClientKeys) -> None:
    """Make ``socket`` (before it connects) a CURVE client of the server in ``keys``."""
    server_public, _ = zmq.auth.load_certificate(keys.server_key_file)
    public, secret = zmq.auth.load_certificate(keys.secret_key_file)
    if secret is None:
        raise SecurityError(f"{keys.secret_key_file} holds no secret key (use the .key_secret file)")
    socket.curve_serverkey = server_public
    socket.curve_publickey = public
    socket.curve_secretkey = secret


_CLIENT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def create_keys(directory: Path, client_name: str = "client") -> dict[str, Path]:
    """Make a client certificate pair ``client_name`` in ``directory`` and allow it in
    (its public certificate copied into ``directory/clients``); make the server's pair
    too unless ``directory`` has it. Refuses to overwrite a client's keys, or to complete
    a server pair of which one half is missing (FileExistsError), and a name that is not
    a plain file name of the client's own (ValueError: it names the key files)."""
    if not _CLIENT_NAME.fullmatch(client_name) or client_name == "server":
        raise ValueError(f"client name {client_name!r}: give 1 to 64 letters, digits, '.', '_' or '-', starting "
                         "with a letter or digit, other than 'server' (it names the client's key files in the folder)")
    names = {
        "server_secret": directory / "server.key_secret",
        "server_public": directory / "server.key",
        "client_secret": directory / f"{client_name}.key_secret",
        "client_public": directory / f"{client_name}.key",
        "clients_dir": directory / "clients",
    }
    existing = [str(names[key]) for key in ("client_secret", "client_public") if names[key].exists()]
    if existing:
        raise FileExistsError(f"refusing to overwrite {', '.join(existing)}")
    server = [names[key].exists() for key in ("server_secret", "server_public")]
    if any(server) and not all(server):
        raise FileExistsError(f"{directory} has half of the server's key pair; refusing to replace it: move that "
                              "half away to make a new pair, or choose another folder")
    names["clients_dir"].mkdir(parents=True, exist_ok=True)
    made = ["server", client_name] if not any(server) else [client_name]
    # Made in a folder of its own (mode 0700) beside them, then linked in: pyzmq writes a secret key with the
    # umask's permissions, and a write that fails (a full disk) must not leave half a pair, which refuses the next.
    staging = Path(tempfile.mkdtemp(prefix=".keys.", dir=directory))
    try:
        for name in made:
            zmq.auth.create_certificates(staging, name)
            (staging / f"{name}.key_secret").chmod(0o600)
        allowed = shutil.copy(staging / names["client_public"].name, staging / "allowed")
        linked: list[Path] = []
        try:
            for name in made:
                for suffix in (".key", ".key_secret"):
                    os.link(staging / f"{name}{suffix}", directory / f"{name}{suffix}")  # never over a file
                    linked.append(directory / f"{name}{suffix}")
            os.replace(allowed, names["clients_dir"] / names["client_public"].name)
        except OSError:
            for path in linked:
                path.unlink(missing_ok=True)
            raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return names
