"""Whatever arrives gets exactly one reply with the right error code, and the server
keeps serving: bad JSON, wrong shapes and types, NaN, unknown commands, huge and
multipart messages, random bytes."""

from __future__ import annotations

import json
import sys

import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexactl.adapters.api.messages import ErrorReply
from hexactl.adapters.api.server import carry_out, decode_body
from hexactl.adapters.api.protocol import MAX_REQUEST_BYTES, TRANSPORT_MAX_BYTES
from hexactl.adapters.api.wire import ApiError, decode_request
from tests.api.support import exchange

STATUS = {"v": 1, "id": "after", "cmd": "status"}
NOT_UTF8: dict[str, bytes] = {  # Python's json.loads(bytes) would accept all of these
    "UTF-16 with BOM": json.dumps(STATUS).encode("utf-16"),
    "UTF-16-BE": json.dumps(STATUS).encode("utf-16-be"),
    "UTF-32 with BOM": json.dumps(STATUS).encode("utf-32"),
    "UTF-32-LE": json.dumps(STATUS).encode("utf-32-le"),
    "UTF-8-encoded surrogate": b'{"v": 1, "id": "\xed\xa0\x80", "cmd": "status"}',
}

CASES: list[tuple[str, bytes, str, object]] = [
    ("not JSON", b"hello", "malformed_json", None),
    ("not UTF-8", b'{"v": 1, "id": 1, "cmd": "status"\xff}', "malformed_json", None),
    ("truncated", b'{"v": 1, "id": 1, "cmd": "sta', "malformed_json", None),
    ("NaN literal", b'{"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, 0, 0, 0, NaN]}', "malformed_json", None),
    ("Infinity literal", b'{"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, 0, 0, 0, -Infinity]}', "malformed_json", None),
    ("overflowing number", b'{"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, 0, 0, 0, 1e400]}', "malformed_json", None),
    ("deep nesting", b"[" * 50_000, "malformed_json", None),
    # Found from outside: an id of 500 nested arrays overflowed the stack of the API's socket
    # thread, which died: nothing was answered again, an E-stop included.
    ("an id nested 500 deep", b'{"v": 1, "id": ' + b"[" * 500 + b"]" * 500 + b', "cmd": "estop"}', "malformed_json", None),
    ("an id nested 33 deep", b'{"v": 1, "id": ' + b"[" * 32 + b"]" * 32 + b', "cmd": "status"}', "malformed_json", None),
    ("integer id beyond double range", b'{"v": 1, "id": 1' + b"0" * 400 + b', "cmd": "status"}', "malformed_json", None),
    ("integer beyond double range", b'{"v": 1, "id": 1, "cmd": "move", "pose": [1' + b"0" * 400 + b', 0, 0, 0, 0, 0]}',
     "malformed_json", None),
    ("integer of 5000 digits", b'{"v": 1, "id": 1' + b"0" * 5000 + b', "cmd": "status"}', "malformed_json", None),
    ("lone surrogate in id", b'{"v": 1, "id": {"a": ["\\ud800"]}, "cmd": "status"}', "invalid_request", None),
    ("JSON array", b'[{"v": 1, "id": 1, "cmd": "status"}]', "invalid_request", None),
    ("JSON string", b'"status"', "invalid_request", None),
    ("missing id", b'{"v": 1, "cmd": "status"}', "invalid_request", None),
    ("missing v", b'{"id": 3, "cmd": "status"}', "invalid_request", 3),
    ("missing cmd", b'{"v": 1, "id": 3}', "invalid_request", 3),
    ("cmd not a string", b'{"v": 1, "id": 3, "cmd": 5}', "invalid_request", 3),
    ("unknown cmd", b'{"v": 1, "id": 3, "cmd": "launch"}', "unknown_command", 3),
    ("wrong version", b'{"v": 2, "id": 3, "cmd": "status"}', "unsupported_version", 3),
    ("version true", b'{"v": true, "id": 3, "cmd": "status"}', "unsupported_version", 3),
    ("extra field", b'{"v": 1, "id": 3, "cmd": "status", "verbose": true}', "invalid_request", 3),
    ("pose too short", b'{"v": 1, "id": 3, "cmd": "move", "pose": [1, 2, 3]}', "invalid_request", 3),
    ("pose of strings", b'{"v": 1, "id": 3, "cmd": "move", "pose": ["1", 0, 0, 0, 0, 0]}', "invalid_request", 3),
    ("leg as float", b'{"v": 1, "id": 3, "cmd": "leg_lock", "leg": 1.0}', "invalid_request", 3),
    ("leg as bool", b'{"v": 1, "id": 3, "cmd": "leg_lock", "leg": true}', "invalid_request", 3),
    ("leg out of range", b'{"v": 1, "id": 3, "cmd": "leg_lock", "leg": 7}', "invalid_request", 3),
    ("negative duration", b'{"v": 1, "id": 3, "cmd": "move", "pose": [0, 0, 0, 0, 0, 0], "duration": -1}', "invalid_request", 3),
    ("progress done over total", b'{"v": 1, "id": 3, "cmd": "progress", "title": "t", "done": 5, "total": 3}',
     "invalid_request", 3),
    ("too large", json.dumps({"v": 1, "id": 3, "cmd": "status", "pad": "x" * MAX_REQUEST_BYTES}).encode(), "too_large", None),
    *((name, body, "malformed_json", None) for name, body in NOT_UTF8.items()),
]


@pytest.mark.parametrize("kind", [zmq.REQ, zmq.DEALER], ids=["REQ", "DEALER"])
@pytest.mark.parametrize(("body", "code", "request_id"), [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_bad_request_gets_its_error_code(shared_service, kind, body, code, request_id) -> None:
    frames = exchange(shared_service.api, [body], kind)
    assert len(frames) == 1
    reply = ErrorReply.model_validate_json(frames[0])
    assert (reply.error.code, reply.id) == (code, request_id)
    assert reply.error.message
    assert _still_serving(shared_service.api)


@pytest.mark.parametrize("body", [*NOT_UTF8.values(), b'{"v": 1, "id": 1, "cmd": "status"\xff}'],
                         ids=[*NOT_UTF8, "invalid byte"])
def test_not_utf8_is_refused_as_such(body) -> None:
    with pytest.raises(ApiError) as refused:
        decode_request(body)
    assert refused.value.code == "malformed_json"
    assert refused.value.message.startswith("not UTF-8: ") and "requests are UTF-8 JSON" in refused.value.message


@pytest.mark.parametrize("digits", [400, 5000])
def test_an_integer_beyond_double_range_is_refused_as_1e400_is(digits) -> None:
    """Found from outside: a 401-digit id was echoed (against the docs), a 401-digit pose
    number was "not a valid number", and a 5000-digit one answered with advice to call
    sys.set_int_max_str_digits() in the service's own interpreter."""
    with pytest.raises(ApiError) as refused:
        decode_request(b'{"v": 1, "id": 1' + b"0" * digits + b', "cmd": "status"}')
    assert refused.value.message == f"not valid JSON: number 1{'0' * 39}… is out of range"
    largest = int(sys.float_info.max)  # a double's range, in full, is accepted
    assert decode_request(f'{{"v": 1, "id": -{largest}, "cmd": "status"}}'.encode()).id == -largest


@pytest.mark.parametrize(("body", "field", "problem"), [
    (b'{"v": 1, "id": 1, "cmd": "move", "pose": [0, 0, 0, 0, 0, 0], "durration": 2}', "durration",
     "not a key here; did you mean duration? the keys here are duration, speed, v, id, deadline_ms, expires_at, pose, "
     "frame, relative, tolerance_mm, validated_under, cmd"),
    (b'{"v": 1, "id": 1, "cmd": "status", "verbose": true}', "verbose",
     "not a key here; the keys here are v, id, deadline_ms, expires_at, cmd"),
    (b'{"v": 1, "id": 1, "cmd": "set_frames", "soft_limit_changes": {"uper": {}}}', "soft_limit_changes.uper",
     "not a key here; did you mean upper? the keys here are lower, upper, max_tilt_deg"),
])
def test_an_unknown_field_is_answered_with_the_fields_taken_there(body, field, problem) -> None:
    with pytest.raises(ApiError) as refused:
        decode_request(body)
    assert refused.value.details == [{"field": field, "problem": problem}]
    assert refused.value.message.endswith(f"{field}: {problem}")


@pytest.mark.parametrize("cmd", ["save_recording", "load_calibration", "play"])
def test_a_path_with_a_line_end_is_refused_saying_to_rename_the_file(cmd) -> None:
    """Found from outside: save_recording wrote a file named with a line end (which the
    log then wrote as two lines); a calibration so named was refused as a "source"."""
    field = "sequence" if cmd == "play" else "path"
    with pytest.raises(ApiError) as refused:
        decode_request(json.dumps({"v": 1, "id": 1, "cmd": cmd, field: "nl\nx.csv"}).encode())
    assert refused.value.code == "invalid_request"
    assert refused.value.message.endswith(f"{field}: 'nl\\nx.csv' is not allowed: a path is one line of text, without "
                                          "control characters (a file named with a line end or a tab: rename it)"), \
        refused.value.message


@pytest.mark.parametrize("body", [b"[" * 50_000, b'{"v": 1, "id": ' + b"[" * 300 + b"]" * 300 + b', "cmd": "status"}'],
                         ids=["beyond the parser", "beyond pydantic's JsonValue"])
def test_nesting_too_deep_says_so_in_a_clients_terms(body) -> None:
    """pydantic's own refusal of an id 300 deep named its every level, and a "cyclic reference"."""
    with pytest.raises(ApiError) as refused:
        decode_request(body)
    assert refused.value.message == "not read: arrays and objects nested too deeply (a request nests 32 levels at most)"


def test_a_request_nesting_32_levels_is_taken() -> None:
    request = decode_request(b'{"v": 1, "id": ' + b"[" * 31 + b"]" * 31 + b', "cmd": "status"}')
    assert request.cmd == "status"


def test_a_lone_surrogate_in_the_id_is_refused_a_pair_accepted() -> None:
    """Echoed, a lone surrogate made the reply's JSON one a strict parser refuses whole."""
    with pytest.raises(ApiError) as refused:
        decode_request(b'{"v": 1, "id": "\\udfff", "cmd": "status"}')
    assert (refused.value.code, refused.value.request_id) == ("invalid_request", None)
    assert "lone UTF-16 surrogate" in refused.value.message
    assert decode_request(b'{"v": 1, "id": "\\ud83d\\ude00", "cmd": "status"}').id == "\U0001f600"


def test_utf8_beyond_ascii_and_a_leading_byte_order_mark_are_accepted() -> None:
    text = json.dumps({"v": 1, "id": "Zürich ✓ 𝄞", "cmd": "status"}, ensure_ascii=False)
    assert decode_request(text.encode()).id == "Zürich ✓ 𝄞"
    assert decode_request(text.encode("utf-8-sig")).id == "Zürich ✓ 𝄞"  # RFC 8259 lets a parser ignore it


@pytest.mark.parametrize(
    ("frames", "code"),
    [
        ([b'{"v": 1, "id": 1, "cmd": "status"}', b"extra"], "invalid_request"),
        ([b"a", b"b", b"c"], "invalid_request"),
        ([b"x" * (MAX_REQUEST_BYTES // 2 + 1)] * 2, "too_large"),
    ],
    ids=["request plus a frame", "three frames", "too large in total"],
)
def test_multipart_is_refused(shared_service, frames, code) -> None:
    reply = json.loads(exchange(shared_service.api, frames)[-1])
    assert reply["error"]["code"] == code and reply["id"] is None
    assert _still_serving(shared_service.api)


def test_empty_request(shared_service) -> None:
    assert json.loads(exchange(shared_service.api, [b""], zmq.REQ)[0])["error"]["code"] == "malformed_json"
    # From a DEALER a lone empty frame is a delimiter with nothing after it.
    delimiter, reply = exchange(shared_service.api, [b""])
    assert delimiter == b"" and json.loads(reply)["error"]["code"] == "invalid_request"


def test_req_envelope_is_kept_for_dealer_that_mimics_req(shared_service) -> None:
    frames = exchange(shared_service.api, [b"", json.dumps(STATUS).encode()])
    assert frames[0] == b"" and json.loads(frames[1])["id"] == "after"


@pytest.mark.parametrize("version", ["1.0", '"1"', "true"])
def test_a_version_of_another_json_type_says_to_send_the_integer(version) -> None:
    """Found from outside: ``"v": 1.0`` (a client whose JSON writes doubles) was answered
    "protocol version 1.0 is not supported" beside ``supported: [1]``."""
    with pytest.raises(ApiError) as refused:
        decode_request(f'{{"v": {version}, "id": 3, "cmd": "status"}}'.encode())
    assert refused.value.code == "unsupported_version" and refused.value.details == {"supported": [1]}
    assert refused.value.message.endswith("v is the JSON integer 1 (no decimal point, no quotes)")


@pytest.mark.parametrize("command, field, value, rule", [
    ("record", "name", "../run", "a recording's name is 1 to 100 letters, digits, '.', '_' or '-'"),
    ("record", "name", "r" * 101, "1 to 100"),
    ("record", "name", "run\n", "starting with a letter or digit"),
    # Found from outside: "r1.json" recorded to r1.json.csv and r1.json.json.
    ("record", "name", "r1.json", "a recording's name is given without extension (run1, not run1.csv: .csv and .json "
                                  "are added)"),
    ("record", "name", "R1.CSV", "given without extension"),
    ("stream_open", "source", "caf\u00e9", "printable ASCII"),
    # Found from outside: a source with a line end forged lines in the service's log (calibration_swapped).
    ("load_calibration", "source", "cal\n2026-11-27 15:00:00,000 WARNING hexactl.safety: loop estop", "one line"),
    ("load_calibration", "source", "cal\u2028forged", "one line"),
    # Found from outside: telemetry carried these to every display as sent, an escape sequence included.
    ("progress", "title", "postures\n2026-11-30 WARNING forged", "one line"),
    ("progress", "label", "\x1b[31mleg 3", "no escape sequence"),
    ("progress", "said", "done\u202eenod", "one line"),
])
def test_a_text_refused_by_its_pattern_says_what_it_may_contain(command, field, value, rule) -> None:
    """Found from outside: ``record`` with ``name: "../run"`` was answered pydantic's "String
    should match pattern '^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$'"."""
    extra = {"record": {"duration_s": 1.0}, "load_calibration": {"toml": ""},
             "progress": {"title": "t", "done": 0, "total": 1}}.get(command, {})
    request = {"v": 1, "id": 1, "cmd": command, **extra, field: value}
    with pytest.raises(ApiError) as refused:
        decode_request(json.dumps(request).encode())
    assert refused.value.code == "invalid_request" and rule in refused.value.message
    assert refused.value.message.startswith(f"{command}: {field}: {value[:120]!r} is not allowed: ")
    assert "pattern" not in refused.value.message and refused.value.details[0]["field"] == field


@pytest.mark.parametrize("fields, field, problem", [
    # Found from outside: pydantic's union refused both kinds of sequence, one of them wrongly:
    # "sequence.str: Input should be a valid string; sequence.InlineSequence.waypoints.0.duration: …".
    ({"cmd": "play", "sequence": {"name": "s", "waypoints": [{"pose": [0] * 6, "duration": "2"}]}},
     "sequence.waypoints[0].duration", "Input should be a valid number"),
    ({"cmd": "play", "sequence": {"name": "s", "waypoints": [{"pose": [0] * 5}]}},
     "sequence.waypoints[0].pose", "a pose is six numbers [x, y, z, roll, pitch, yaw], got 5"),
    ({"cmd": "play", "sequence": ["x_sweep"]},
     "sequence", "a sequence is its name (a string) or the sequence itself (an object), got an array"),
    ({"cmd": "validate_pose", "pose": [0, 0, 0, 0, 0, None]}, "pose[5]", "Input should be a valid number"),
    # pydantic's location of a key at fault was "axes.q.[key]"
    ({"cmd": "wave", "frequency_hz": 1.0, "cycles": 1, "axes": {"q": {"amplitude": 1.0}}},
     "axes.q (the key)", "Input should be 'x', 'y', 'z', 'roll', 'pitch' or 'yaw'"),
])
def test_a_problem_is_told_once_where_a_client_would_write_it(fields, field, problem) -> None:
    with pytest.raises(ApiError) as refused:
        decode_request(json.dumps({"v": 1, "id": 1, **fields}).encode())
    assert refused.value.code == "invalid_request"
    assert refused.value.details == [{"field": field, "problem": problem}]
    assert refused.value.message == f"{fields['cmd']}: {field}: {problem}"


def test_a_sequence_is_played_by_its_name_or_given_whole() -> None:
    named = decode_request(json.dumps({"v": 1, "id": 1, "cmd": "play", "sequence": "x_sweep"}).encode())
    given = decode_request(json.dumps({"v": 1, "id": 1, "cmd": "play", "sequence": {
        "name": "s", "waypoints": [{"pose": [1, 0, 0, 0, 0, 0], "duration": 2}]}}).encode())
    assert named.sequence == "x_sweep"
    assert given.sequence.name == "s" and given.sequence.waypoints[0].duration == 2.0


def test_a_calibrations_source_may_be_any_one_line_path() -> None:
    request = {"v": 1, "id": 1, "cmd": "load_calibration", "toml": "", "source": "/home/jos\u00e9/cal 2.toml"}
    assert decode_request(json.dumps(request).encode()).source == "/home/jos\u00e9/cal 2.toml"


def test_a_streams_timeout_is_bounded_below_by_the_loops_rule_only() -> None:
    """Found in review: the request refused timeout_ms under 5, a rule of its own beside the
    loop's 3 cycles (3 ms at 1000 Hz): one rule, in the loop (tests/control/test_stream.py)."""
    request = {"v": 1, "id": 1, "cmd": "stream_open", "source": "sim"}
    assert decode_request(json.dumps({**request, "timeout_ms": 3.5}).encode()).timeout_ms == 3.5
    with pytest.raises(ApiError, match="stream_open: timeout_ms: Input should be greater than 0"):
        decode_request(json.dumps({**request, "timeout_ms": 0}).encode())


def test_handler_bug_becomes_internal_error() -> None:
    def broken(request, deadline_ns, sender):
        raise KeyError("boom")

    reply = json.loads(carry_out(decode_body([json.dumps(STATUS).encode()]), broken, None, None))
    assert reply["error"]["code"] == "internal_error" and reply["id"] == "after"


def test_non_finite_reply_becomes_internal_error() -> None:
    reply = json.loads(carry_out(decode_body([json.dumps(STATUS).encode()]), lambda request, deadline_ns, sender: {"value": float("nan")}, None, None))
    assert reply["error"]["code"] == "internal_error"


def test_frame_beyond_transport_limit_does_not_stop_the_server(shared_service) -> None:
    # ZeroMQ drops such a peer without delivering anything (documented); the server carries on.
    context = zmq.Context.instance()
    with context.socket(zmq.DEALER) as socket:
        socket.linger = 0
        socket.connect(shared_service.api)
        socket.send(b"x" * (TRANSPORT_MAX_BYTES + 1))
    assert _still_serving(shared_service.api)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=20,
)
requestish = st.fixed_dictionaries(
    {"v": st.sampled_from([1, 1, 2, "1"]), "id": json_values, "cmd": st.sampled_from(["status", "move", "leg_lock", "play", "x"])},
    optional={"pose": json_values, "leg": json_values, "sequence": json_values, "duration": json_values},
)
bodies = st.one_of(
    st.binary(max_size=200),
    json_values.map(lambda value: json.dumps(value).encode()),
    requestish.map(lambda value: json.dumps(value).encode()),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames=st.lists(bodies, min_size=1, max_size=3))
def test_fuzz_exactly_one_reply(shared_service, frames) -> None:
    # The fuzz message, then a status: the next two replies must be the fuzz reply and
    # the status reply, in order. A missing or duplicated reply breaks the pairing.
    context = zmq.Context.instance()
    with context.socket(zmq.DEALER) as socket:
        socket.linger = 0
        socket.connect(shared_service.api)
        socket.send_multipart(frames)
        socket.send(json.dumps(STATUS).encode())
        replies = []
        for _ in range(2):
            assert socket.poll(5000), "a reply is missing"
            replies.append(json.loads(socket.recv_multipart()[-1]))
        assert socket.poll(0) == 0, "an extra reply"
    assert set(replies[0]) >= {"v", "id", "ok"}
    assert replies[1]["id"] == "after" and replies[1]["ok"]


def _still_serving(endpoint: str) -> bool:
    return json.loads(exchange(endpoint, [json.dumps(STATUS).encode()])[-1])["ok"]
