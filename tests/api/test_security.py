"""Remote access: loopback is open, anything else needs CURVE, and CURVE works end to end."""

from __future__ import annotations

import errno
import json

import pytest
import zmq

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber, ZmqConnection
from hexactl.adapters.api.security import (
    CurveClientKeys,
    CurveServer,
    CurveServerKeys,
    SecurityError,
    check_endpoints,
    client_keys,
    create_keys,
)
from hexactl.adapters.api.protocol import is_local_endpoint
from hexactl.adapters.api.server import ApiServer
from hexactl.adapters.api.stream_receiver import StreamReceiver
from hexactl.adapters.api.stream_wire import encode
from hexactl.adapters.api.telemetry import TelemetryPublisher
from hexactl.control.stream import StreamPhase, StreamProgress
from hexactl.control.stream_commands import TargetResult
from tests.reliability.support import wait_for
from tools.serving import unserved_endpoint


@pytest.mark.parametrize(
    ("endpoint", "local"),
    [
        ("tcp://127.0.0.1:5555", True),
        ("tcp://127.3.2.1:5555", True),
        ("tcp://localhost:5555", True),
        ("tcp://[::1]:5555", True),
        ("tcp://lo:5555", True),
        ("ipc:///tmp/hexactl.sock", True),
        ("inproc://api", True),
        ("tcp://*:5555", False),
        ("tcp://0.0.0.0:5555", False),
        ("tcp://192.168.1.10:5555", False),
        ("tcp://eth0:5555", False),
        ("tcp://[::]:5555", False),
        ("tcp://controller.example.org:5555", False),
        ("ws://127.0.0.1:5555", False),
    ],
)
def test_which_endpoints_are_local(endpoint, local) -> None:
    assert is_local_endpoint(endpoint) is local


def test_non_loopback_bind_needs_curve(tmp_path) -> None:
    with pytest.raises(SecurityError, match="refusing to bind tcp://0.0.0.0:5555 without CURVE"):
        check_endpoints(["tcp://127.0.0.1:5555", "tcp://0.0.0.0:5555"], None)
    check_endpoints(["tcp://127.0.0.1:5555", "ipc:///tmp/x"], None)
    with pytest.raises(SecurityError, match="does not exist"):
        check_endpoints(["tcp://0.0.0.0:5555"], CurveServerKeys(tmp_path / "missing", tmp_path))
    keys = create_keys(tmp_path / "keys")
    check_endpoints(["tcp://0.0.0.0:5555"], CurveServerKeys(keys["server_secret"], keys["clients_dir"]))


def test_a_clients_folder_that_would_let_no_client_in_is_refused_naming_why(tmp_path) -> None:
    """Found from outside: one bad *.key among the clients' made ZeroMQ load none (logged by
    zmq.auth only), and the service started saying CURVE: every client locked out. A file
    for the folder said the folder "does not exist"."""
    keys = create_keys(tmp_path / "keys")
    clients = keys["clients_dir"]
    assert client_keys(clients) == ["client"]
    (clients / "junk.key").write_text("junk\n")
    with pytest.raises(SecurityError, match=r"clients directory .*: junk.key \(.*\) is not a client's public key, "
                                            r"and ZeroMQ would then let no client in: remove it"):
        check_endpoints(["tcp://0.0.0.0:5555"], CurveServerKeys(keys["server_secret"], clients))
    (clients / "junk.key").unlink()
    with pytest.raises(SecurityError, match="is a file: name the folder of the clients' public keys"):
        client_keys(clients / "client.key")
    (clients / "client.key").unlink()
    with pytest.raises(SecurityError, match="holds no client key \\(\\*.key\\): no client could connect"):
        client_keys(clients)


def test_create_keys_adds_clients_and_never_overwrites(tmp_path) -> None:
    keys = create_keys(tmp_path)
    assert (keys["server_secret"].stat().st_mode & 0o777) == 0o600
    assert (keys["clients_dir"] / "client.key").is_file()
    server_key = keys["server_secret"].read_text()
    with pytest.raises(FileExistsError):
        create_keys(tmp_path)
    laptop = create_keys(tmp_path, "laptop")
    assert keys["server_secret"].read_text() == server_key  # kept
    assert (laptop["clients_dir"] / "laptop.key").is_file() and (laptop["client_secret"].stat().st_mode & 0o777) == 0o600
    keys["server_public"].unlink()
    with pytest.raises(FileExistsError, match="half of the server's key pair"):
        create_keys(tmp_path, "other")


@pytest.mark.parametrize("name", ["../../evil", "", "a/b", ".hidden", "server", "x" * 65, "tab\tname"])
def test_a_client_name_that_is_not_a_plain_name_of_its_own_writes_nothing(tmp_path, name: str) -> None:
    """The name names the key files: a path in it wrote them outside the folder, an empty
    one hidden files, and 'server' is the server's pair."""
    with pytest.raises(ValueError, match="client name"):
        create_keys(tmp_path / "keys", name)
    assert sorted(tmp_path.rglob("*")) == []


def test_curve_end_to_end(tmp_path) -> None:
    keys = create_keys(tmp_path / "keys", "alice")
    stranger = create_keys(tmp_path / "stranger")  # a client whose key is not in clients/
    context = zmq.Context()
    curve = CurveServer(context, CurveServerKeys(keys["server_secret"], keys["clients_dir"]))
    server = ApiServer(context, "tcp://127.0.0.1:*", lambda request, deadline_ns, sender: {"message": sender}, curve)
    server.start()
    try:
        allowed = CurveClientKeys(keys["server_public"], keys["client_secret"])
        with HexactlClient(server.endpoint, curve=allowed, name="I say I am bob") as client:
            # The name is the client's word; the key's name is the authenticator's.
            assert client.call("status")["message"] == "I say I am bob (127.0.0.1, key alice)"
        refused = CurveClientKeys(keys["server_public"], stranger["client_secret"])
        with HexactlClient(server.endpoint, timeout_s=0.5, curve=refused) as client:
            with pytest.raises(ServiceUnavailable, match="does not know this client's key.*check both keys"):
                client.call("status")
        with context.socket(zmq.DEALER) as plain:  # no CURVE at all: nothing gets through
            plain.linger = 0
            plain.sndtimeo = 500
            plain.connect(server.endpoint)
            try:
                plain.send(json.dumps({"v": 1, "id": 1, "cmd": "status"}).encode())
            except zmq.Again:  # the server refused the handshake before the send: no peer to queue for
                pass
            assert plain.poll(500) == 0
    finally:
        server.close()
        curve.close()
        context.term()


def test_curve_telemetry_and_pose_stream_get_through_their_message_bounds(tmp_path) -> None:
    """The telemetry and stream sockets close a connection whose message exceeds their
    bound (MAXMSGSIZE); the CURVE handshake's messages, the largest a subscriber or a
    stream's sender sends, still fit."""
    keys = create_keys(tmp_path / "keys", "alice")
    allowed = CurveClientKeys(keys["server_public"], keys["client_secret"])
    context = zmq.Context()
    curve = CurveServer(context, CurveServerKeys(keys["server_secret"], keys["clients_dir"]))
    publisher = TelemetryPublisher(context, "tcp://127.0.0.1:*", lambda: {"state": "disabled"}, 100.0, curve)
    targets: list[int] = []
    progress = StreamProgress(1, "test", "zero", StreamPhase.FOLLOWING, timeout_ns=10**9)
    receiver = StreamReceiver(context, "tcp://127.0.0.1:*", None,
                              lambda pose, sequence, *_: targets.append(sequence) or TargetResult(True), 0.01,
                              lambda: progress, curve)
    publisher.start()
    receiver.start()
    try:
        with TelemetrySubscriber(publisher.endpoint, curve=allowed) as telemetry:
            assert telemetry.receive(timeout_s=30.0) == {"state": "disabled"}
        with ZmqConnection(zmq.PUSH, receiver.endpoint, allowed, {}) as push:
            push.socket.send(encode(1, 0.0, [0.0] * 6))
            wait_for(lambda: targets == [1], "the sample through CURVE")
    finally:
        receiver.close()
        publisher.close()
        curve.close()
        context.term()


def test_create_keys_on_a_full_disk_leaves_no_half_pair(tmp_path, monkeypatch) -> None:
    """A key pair half written (an empty server.key on a full disk) refused every later
    `hexactl keys` there: 'has half of the server's key pair'."""
    import zmq.auth

    real = zmq.auth.create_certificates

    def full_after_the_server(directory, name, *arguments, **options):
        if name != "server":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(directory, name, *arguments, **options)

    monkeypatch.setattr(zmq.auth, "create_certificates", full_after_the_server)
    with pytest.raises(OSError, match="No space left"):
        create_keys(tmp_path / "keys")
    assert [path.name for path in (tmp_path / "keys").iterdir()] == ["clients"]
    monkeypatch.undo()
    keys = create_keys(tmp_path / "keys")
    assert keys["server_secret"].is_file() and (keys["clients_dir"] / "client.key").is_file()


def test_no_answer_from_beyond_localhost_without_keys_names_curve() -> None:
    """Found from outside: a service beyond localhost drops a client without CURVE keys
    without a word, and the client asked only whether the service was running."""
    with HexactlClient("tcp://192.0.2.1:5555", timeout_s=0.05) as client:  # TEST-NET-1: nobody answers
        with pytest.raises(ServiceUnavailable, match="beyond localhost answers only clients with CURVE keys"):
            client.call("status")
    with HexactlClient(unserved_endpoint(), timeout_s=0.05) as client:
        with pytest.raises(ServiceUnavailable) as local:
            client.call("status")
    assert str(local.value).endswith("is `hexactl serve` running there?")
