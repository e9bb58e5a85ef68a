"""The Python client: a request it cannot send is refused before sending, naming why, and
the service's answer to a request it could not read is the reply, not a time-out."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import zmq

from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable
from hexactl.adapters.api.server import sender_of
from hexactl.adapters.api.protocol import MAX_REQUEST_BYTES, TRANSPORT_MAX_BYTES

WAIT_S = 30.0  # bounds a hang only: a reply takes milliseconds


def test_a_request_too_large_to_read_gets_its_error_not_a_timeout(shared_service) -> None:
    with HexactlClient(shared_service.api, timeout_s=WAIT_S) as client:
        reply = client.request("stream_open", source="x" * MAX_REQUEST_BYTES)
        assert reply["ok"] is False and reply["error"]["code"] == "too_large" and reply["id"] is None
        assert client.call("status")["ok"]  # and the next request gets its own reply


def test_a_request_too_large_for_the_service_to_read_is_refused_before_sending() -> None:
    """Found from outside: a 2 MB calibration said "no answer within 5 s: is hexactl serve
    running there?": ZeroMQ drops a message beyond the transport's limit, unanswered."""
    with HexactlClient("tcp://127.0.0.1:9", timeout_s=0.1) as client:  # nobody there: nothing may be sent
        with pytest.raises(ValueError, match=f"load_calibration: a request of [0-9]+ bytes: the API answers "
                                             f"{MAX_REQUEST_BYTES} at most"):
            client.request("load_calibration", toml="#" * TRANSPORT_MAX_BYTES)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_number_that_is_not_finite_is_refused_before_sending(value: float) -> None:
    with HexactlClient("tcp://127.0.0.1:9", timeout_s=0.1) as client:  # nobody there: nothing may be sent
        with pytest.raises(ValueError, match="move: the API takes finite numbers only"):
            client.request("move", pose=[0, 0, value, 0, 0, 0])


@pytest.mark.parametrize("field", ["v", "id", "cmd"])
def test_the_envelope_is_not_a_commands_field(field: str) -> None:
    with HexactlClient("tcp://127.0.0.1:9", timeout_s=0.1) as client:
        with pytest.raises(ValueError, match=f"status: {field}: the request's envelope"):
            client.request("status", **{field: 1})


def test_self_is_a_field_like_any_other(shared_service) -> None:
    """Found from outside: ``request(cmd, **fields)`` took ``self`` as its own argument."""
    with HexactlClient(shared_service.api, timeout_s=WAIT_S) as client:
        reply = client.request("status", self=1)
        assert reply["error"]["code"] == "invalid_request" and "self" in reply["error"]["message"]


UNCLOSED_CLIENTS = """
import gc
from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable, TelemetrySubscriber

client = HexactlClient("tcp://127.0.0.1:9", timeout_s=0.05)  # nobody there: it times out
try:
    client.request("status")
except ServiceUnavailable:
    pass
holder = {"telemetry": TelemetrySubscriber("tcp://127.0.0.1:9")}
holder["itself"] = holder  # a cycle, as any object holding a client and a bound method of its own has
del client, holder
gc.collect()
print("collected")
"""


def test_a_client_left_unclosed_is_collected_without_hanging_its_program() -> None:
    """Found from outside: a client dropped without close() (the README's example never
    closes it) after a time-out hung its program for ever at the next garbage collection:
    its private ZeroMQ context's finaliser waited for a socket the collector had not closed."""
    done = subprocess.run([sys.executable, "-W", "ignore::ResourceWarning", "-c", UNCLOSED_CLIENTS],
                          capture_output=True, text=True, timeout=120)  # a hang guard only
    assert done.returncode == 0 and done.stdout.strip() == "collected", done.stderr


def test_an_empty_name_is_an_unnamed_client() -> None:
    """Found from outside: ``HexactlClient(endpoint, name="")`` raised ZMQError 'Invalid
    argument' (ZeroMQ takes no empty connection property), naming nothing."""
    context = zmq.Context.instance()
    with context.socket(zmq.ROUTER) as router:
        router.linger = 0
        port = router.bind_to_random_port("tcp://127.0.0.1")
        with HexactlClient(f"tcp://127.0.0.1:{port}", timeout_s=0.5, name="") as client:
            with pytest.raises(ServiceUnavailable):  # nobody answers: the request is all this needs
                client.request("status")
        assert router.poll(WAIT_S * 1000)
        frames = router.recv_multipart(copy=False)
        assert sender_of(frames[-1]) == "an unnamed client (127.0.0.1)"
