"""Bad input is refused with a clear error while the loop keeps its rate: every kind the
API knows to refuse is sent to the real service while it holds the platform enabled,
and each gets its error; meanwhile nothing that parses, validates or plans a request
runs in the loop's process (this one: the service's API runs in a process of its own),
so none of it can hold the loop's GIL; the loop went on cycling with no fault latched,
and the loop link dropped nothing. The timing itself is benchmarked, not asserted
(BENCHMARKS.md: tools/bench_service.py and tools/fuzz_api.py)."""

from __future__ import annotations

import json
from collections import Counter

import pytest
import zmq

import hexactl.adapters.api.commands as commands_module
import hexactl.adapters.api.server as server_module
import hexactl.control.move_commands as move_commands_module
import hexactl.control.sequence_commands as sequence_commands_module
from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.geometry_file import geometry_to_toml
from hexactl.application.service import Service
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import WAIT_S, status
from tests.reliability.support import enable


def raw_requests() -> list[tuple[bytes, str]]:
    """(request body, the error code it must get) for what no client library would send."""
    return [
        (b"{not json", "malformed_json"),
        (b"\xff\xfe\x00garbage", "malformed_json"),
        (json.dumps({"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, "NaN", 0, 0, 0]}).encode(), "invalid_request"),
        (b'{"v": 1, "id": 2, "cmd": "move", "pose": [0, 0, NaN, 0, 0, 0]}', "malformed_json"),
        (b'{"v": 1, "id": 3, "cmd": "move", "pose": [0, 0, Infinity, 0, 0, 0]}', "malformed_json"),
        (json.dumps({"v": 1, "id": 4, "cmd": "move", "pose": "up"}).encode(), "invalid_request"),
        (json.dumps({"v": 1, "id": 5, "cmd": "leg_lock", "leg": 7}).encode(), "invalid_request"),
        (json.dumps({"v": 1, "id": 6, "cmd": "launch_missiles"}).encode(), "unknown_command"),
        (json.dumps({"v": 2, "id": 7, "cmd": "status"}).encode(), "unsupported_version"),
        (b"[" * 30_000 + b"]" * 30_000, "malformed_json"),  # nested past any parser's depth
        (b" " * 200_000, "too_large"),
    ]


def request_errors(client: HexactlClient, nominal: Geometry) -> list[tuple[str, dict, str]]:
    """(command, fields, the error code it must get) for well-formed requests with bad content."""
    broken = geometry_to_toml(nominal).replace("zero_lengths", "zero_lenghts")
    return [
        ("move", {"pose": [5000, 0, 0, 0, 0, 0]}, "path_violation"),
        ("move", {"pose": [0, 0, 0, 0, 0, 80]}, "path_violation"),
        ("move", {"pose": [0, 0, -900, 0, 0, 0]}, "path_violation"),
        ("load_calibration", {"toml": broken}, "invalid_calibration"),
        ("load_calibration", {"toml": "zero_lengths = [1]"}, "invalid_calibration"),
        ("load_calibration", {"path": "/etc/passwd"}, "forbidden_path"),
        ("play", {"sequence": "no_such_sequence"}, "unknown_sequence"),
        ("play", {"sequence": {"name": "far", "waypoints": [{"pose": [0, 0, 0, 0, 90, 0]}]}}, "path_violation"),
    ]


@pytest.fixture
def handled_here(monkeypatch: pytest.MonkeyPatch) -> Counter:
    """Counts calls, in this process, of what parses, handles and plans requests."""
    calls: Counter = Counter()

    def counting(module, name: str) -> None:
        original = getattr(module, name)

        def wrapper(*args, **kwargs):
            calls[name] += 1
            return original(*args, **kwargs)

        monkeypatch.setattr(module, name, wrapper)

    counting(server_module, "decode_request")
    counting(commands_module, "parse_geometry")
    counting(move_commands_module, "plan_path")
    counting(sequence_commands_module, "plan_path")
    counting(commands_module.CommandHandler, "__call__")
    return calls


def test_bad_input_is_refused_while_the_loop_runs_on(service: Service, client: HexactlClient, nominal: Geometry,
                                                     handled_here: Counter) -> None:
    enable(client)
    before = status(client)
    context = zmq.Context.instance()
    raw = context.socket(zmq.DEALER)
    raw.linger = 0
    raw.connect(service.api_endpoint)
    try:
        for body, code in raw_requests():
            raw.send_multipart([b"", body])
            assert raw.poll(WAIT_S * 1000), f"no reply to {body[:40]!r}"
            reply = json.loads(raw.recv_multipart()[-1])
            assert reply["ok"] is False and reply["error"]["code"] == code, (body[:60], reply)
            assert reply["error"]["message"]
    finally:
        raw.close()
    for cmd, fields, code in request_errors(client, nominal):
        reply = client.request(cmd, **fields)
        assert reply["ok"] is False and reply["error"]["code"] == code, (cmd, fields, reply)
        assert reply["error"]["message"]
    after = status(client)

    assert handled_here == Counter()  # not one request was parsed, handled or planned in the loop's process
    assert after["state"] == "enabled" and after["faults"] == [] and after["calibration_id"] == before["calibration_id"]
    assert after["loop"]["cycles"] > before["loop"]["cycles"]
    assert service.link.rejected == 0 and service.link.commands_open
    print(f"loop during the bad input: {after['loop']['cycles'] - before['loop']['cycles']} cycles, "
          f"{after['loop']['missed'] - before['loop']['missed']} missed, "
          f"lateness max {after['loop']['lateness_us']['max']:.0f} µs over the run")
