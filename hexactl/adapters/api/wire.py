"""Bytes on the wire ↔ messages: request decoding with one error code per way a
request can be wrong, reply encoding, and the ROUTER envelope.

Nothing here raises for bad input except :class:`ApiError`, which carries the code,
message and the request's ``id`` when it could be read.
"""

from __future__ import annotations

import codecs
import dataclasses
import json
import sys
from collections import Counter
from collections.abc import Mapping
from enum import Enum, StrEnum
from math import isfinite
from typing import Any

import numpy as np
from pydantic import BaseModel, TypeAdapter, ValidationError

from hexactl.adapters.api.messages import COMMANDS, REQUEST_MODELS, Request, json_type
from hexactl.adapters.api.protocol import MAX_REQUEST_BYTES, PROTOCOL_VERSION
from hexactl.kinematics.validation_messages import problem_message, validation_location



class ErrorCode(StrEnum):
    """The API's own error codes. The controller's refusals add theirs
    (:class:`hexactl.control.results.ErrorCode`: ``not_enabled``, ``path_violation``, …),
    passed through unchanged."""

    MALFORMED_JSON = "malformed_json"  # not UTF-8 (UTF-16/32 are refused) or not JSON, or NaN/Infinity/out-of-range
    INVALID_REQUEST = "invalid_request"  # not an object, missing id/v/cmd, wrong types or values, multipart
    UNKNOWN_COMMAND = "unknown_command"
    UNSUPPORTED_VERSION = "unsupported_version"
    TOO_LARGE = "too_large"
    FORBIDDEN_PATH = "forbidden_path"  # a file outside the data directories
    FILE_NOT_FOUND = "file_not_found"  # or a file that cannot be read
    WRITE_FAILED = "write_failed"  # a file could not be written (a full disk, permissions): the message says why
    FILE_EXISTS = "file_exists"  # save_recording never overwrites
    INVALID_CALIBRATION = "invalid_calibration"  # the calibration text or file is refused
    INVALID_SEQUENCE = "invalid_sequence"  # the sequence file is refused
    UNKNOWN_SEQUENCE = "unknown_sequence"
    NO_RECORDING = "no_recording"  # save_recording before any sequence was played
    NO_RECORDER = "no_recorder"  # record on a handler built without the data recorder's writer
    NOT_RECORDING = "not_recording"  # record_stop with no recording under way
    NO_STREAM_INPUT = "no_stream_input"  # stream_open on a handler built without a stream receiver
    NO_INSTRUMENT = "no_instrument"  # measure on a service without a measuring instrument (real actuators)
    MEASUREMENT_FAILED = "measurement_failed"  # the instrument could not measure (the simulated platform has no pose)
    BUSY = "busy"  # too many requests queued from this client (or from all): wait for replies
    EXPIRED = "expired"  # its deadline_ms or expires_at passed before it could be carried out; it never will be
    CANCELLED = "cancelled"  # a motion request still queued when a stop, abort or estop arrived
    INTERNAL_ERROR = "internal_error"  # a bug: logged with its traceback


class ApiError(Exception):
    """A request that cannot be carried out; becomes an error reply."""

    def __init__(self, code: str, message: str, details: Any = None, request_id: Any = None) -> None:
        super().__init__(message)
        self.code = str(code)
        self.message = message
        self.details = details
        self.request_id = request_id


def problems_error(code: str, text: str) -> ApiError:
    """An ApiError for a refusal listing one problem per line (a geometry or sequence
    error): the first problem (and the count) as the message, every line in details."""
    lines = text.splitlines() or [text]
    message = lines[0] if len(lines) == 1 else f"{len(lines)} problems, first: {lines[0]}"
    return ApiError(code, message, lines)


MAX_NESTING = 32
"""The deepest a request's arrays and objects nest (the deepest command's nest 4 levels)."""

_TOO_DEEP = f"not read: arrays and objects nested too deeply (a request nests {MAX_NESTING} levels at most)"

_REQUEST = TypeAdapter(Request)
_REQUEST_MODEL = dict(zip(COMMANDS, REQUEST_MODELS))


def decode_request(body: bytes) -> Request:
    """The request in one frame, validated; :class:`ApiError` says what is wrong.

    The checks run in order, so each bad request gets the most specific code: size,
    JSON, object, ``id``, ``v``, ``cmd``, then the command's own fields.
    """
    if len(body) > MAX_REQUEST_BYTES:
        raise ApiError(ErrorCode.TOO_LARGE, f"request of {len(body)} bytes; the limit is {MAX_REQUEST_BYTES}")
    try:
        document = json.loads(_utf8_text(body), parse_constant=_refuse_constant, parse_float=_finite_float,
                              parse_int=_double_range_int, object_pairs_hook=_unique_keys)
    except _DuplicateKey as error:
        raise ApiError(ErrorCode.INVALID_REQUEST, f"key {error.key[:100]!r} appears twice in one object: "
                       "give each key once") from None
    except RecursionError:
        raise ApiError(ErrorCode.MALFORMED_JSON, _TOO_DEEP) from None
    except ValueError as error:  # JSONDecodeError is a ValueError
        raise ApiError(ErrorCode.MALFORMED_JSON, f"not valid JSON: {_first_line(error)}") from None
    if _deeper_than(document, MAX_NESTING):  # pydantic's JsonValue took an id of 300 levels for a cycle
        raise ApiError(ErrorCode.MALFORMED_JSON, _TOO_DEEP)
    if not isinstance(document, dict):
        raise ApiError(ErrorCode.INVALID_REQUEST, f"a request is a JSON object, got {json_type(document)}")
    if "id" not in document:
        raise ApiError(ErrorCode.INVALID_REQUEST, "missing id")
    request_id = document["id"]
    if not _unicode(request_id):  # echoed as is, it would make the reply's JSON unreadable to a strict parser
        raise ApiError(ErrorCode.INVALID_REQUEST, "id holds a lone UTF-16 surrogate (\\ud800-\\udfff unpaired): "
                       "not Unicode text; use another id")
    version = document.get("v")
    if "v" not in document:
        raise ApiError(ErrorCode.INVALID_REQUEST, f"missing v (the protocol version, {PROTOCOL_VERSION})", request_id=request_id)
    if type(version) is not int or version != PROTOCOL_VERSION:  # type(): true is not 1
        # A JSON library that writes every number as a double sends 1.0: say what to send.
        form = "" if type(version) is int else f": v is the JSON integer {PROTOCOL_VERSION} (no decimal point, no quotes)"
        raise ApiError(
            ErrorCode.UNSUPPORTED_VERSION,
            f"protocol version {json.dumps(version)} is not supported{form}",
            {"supported": [PROTOCOL_VERSION]},
            request_id,
        )
    command = document.get("cmd")
    if not isinstance(command, str):
        raise ApiError(ErrorCode.INVALID_REQUEST, "cmd must be a command name (a string)", request_id=request_id)
    if command not in COMMANDS:
        raise ApiError(
            ErrorCode.UNKNOWN_COMMAND, f"unknown command {command[:100]!r}", {"commands": list(COMMANDS)}, request_id
        )
    try:
        return _REQUEST.validate_python(document)
    except ValidationError as error:
        problems = validation_problems(error, _REQUEST_MODEL[command], within_command=True)
        message = "; ".join(f"{p['field']}: {p['problem']}" if p["field"] else p["problem"] for p in problems)
        raise ApiError(ErrorCode.INVALID_REQUEST, f"{command}: {message}", problems, request_id) from None


def validation_problems(error: ValidationError, model: type[BaseModel],
                        within_command: bool = False) -> list[dict[str, str]]:
    """An ``invalid_request``'s ``details``: one ``{field, problem}`` per problem of validating
    ``model``, the field as a client writes it (``within_command``: the locations start with
    the command's tag, left out); an unknown field is answered with the fields taken."""
    problems = []
    for problem in error.errors(include_url=False, include_input=False, include_context=False):
        location = problem["loc"][1:] if within_command else problem["loc"]
        problems.append({"field": validation_location(location),
                         "problem": problem_message({**problem, "loc": location}, model)})
    return problems


def encode(document: dict[str, Any]) -> bytes:
    """Compact JSON, ASCII (so an echoed id with a lone surrogate still encodes); raises
    ValueError for NaN or infinity, which are not JSON."""
    return json.dumps(document, allow_nan=False, separators=(",", ":")).encode("ascii")


def jsonable(value: Any) -> Any:
    """``value`` with dataclasses, pydantic models, mappings, tuples, enums and numpy scalars turned into
    JSON types, and non-finite floats into null (JSON has no NaN)."""
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {field.name: jsonable(getattr(value, field.name)) for field in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.generic):  # numpy scalars from the kinematics
        value = value.item()
    if isinstance(value, float) and not isfinite(value):
        return None
    return value


def ok_reply(request_id: Any, **fields: Any) -> dict[str, Any]:
    return {"v": PROTOCOL_VERSION, "id": request_id, "ok": True, **fields}


def error_body(code: str, message: str, details: Any = None) -> dict[str, Any]:
    """The ``error`` object of an error reply; ``details`` left out when None or empty."""
    body: dict[str, Any] = {"code": str(code), "message": message}
    if details:
        body["details"] = details
    return body


def error_reply(request_id: Any, code: str, message: str, details: Any = None) -> dict[str, Any]:
    return {"v": PROTOCOL_VERSION, "id": request_id, "ok": False, "error": error_body(code, message, details)}


def split_envelope(frames: list[bytes]) -> tuple[list[bytes], list[bytes]]:
    """(envelope, body) of a message received on a ROUTER socket.

    The envelope is the routing identity plus, for REQ clients (and DEALERs that mimic
    them), every frame up to the first empty delimiter; the body is what follows. A
    plain DEALER's message has no delimiter: its envelope is the identity alone. The
    reply goes back with the same envelope.
    """
    for index in range(1, len(frames)):
        if not frames[index]:
            return frames[: index + 1], frames[index + 1 :]
    return frames[:1], frames[1:]


def _utf8_text(body: bytes) -> str:
    """``body`` decoded as UTF-8; :class:`ApiError` ``malformed_json`` naming the problem
    otherwise. ``json.loads`` would guess UTF-16 and UTF-32 from the first bytes and let
    UTF-8-encoded surrogates through: the API's requests are UTF-8 only. A leading UTF-8
    byte-order mark is dropped, as RFC 8259 allows a parser to."""
    nul = body.find(b"\0")
    if nul >= 0:  # never in UTF-8 JSON (U+0000 must be escaped), always in UTF-16 or UTF-32 JSON
        raise ApiError(ErrorCode.MALFORMED_JSON,
                       f"not UTF-8: a NUL byte at offset {nul} (UTF-16 or UTF-32?); requests are UTF-8 JSON")
    # Stripped here, not by the utf-8-sig codec: Python loads that from disk at its first use,
    # and answering a request opens no file outside the data directories.
    unmarked = body.removeprefix(codecs.BOM_UTF8)
    try:
        return unmarked.decode("utf-8")  # strict: invalid sequences and encoded surrogates raise
    except UnicodeDecodeError as error:
        offset = error.start + len(body) - len(unmarked)
        raise ApiError(ErrorCode.MALFORMED_JSON,
                       f"not UTF-8: {error.reason} at offset {offset}; requests are UTF-8 JSON") from None


class _DuplicateKey(Exception):
    """An object with a key twice (not a ValueError: that would read as malformed JSON)."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # JSON leaves duplicate keys undefined and Python keeps the last: a request that says
    # two things must not be read as one of them.
    document = dict(pairs)
    if len(document) != len(pairs):
        raise _DuplicateKey(next(key for key, count in Counter(key for key, _ in pairs).items() if count > 1))
    return document


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON (numbers must be finite)")


def _finite_float(text: str) -> float:
    value = float(text)
    if not isfinite(value):
        raise ValueError(f"number {text[:40]} is out of range")
    return value


_LARGEST_DOUBLE = int(sys.float_info.max)
_LONGEST_DOUBLE_TEXT = len(str(-_LARGEST_DOUBLE))


def _double_range_int(text: str) -> int:
    # As _finite_float: a client's JSON library reads numbers as doubles, and Python's int()
    # of over 4300 digits would answer with advice for the service's own interpreter.
    if len(text) > _LONGEST_DOUBLE_TEXT or abs(value := int(text)) > _LARGEST_DOUBLE:
        raise ValueError(f"number {text[:40]}{'…' if len(text) > 40 else ''} is out of range")
    return value


def _deeper_than(value: object, levels: int) -> bool:
    """Whether arrays and objects in ``value`` (a parsed JSON value) nest more than
    ``levels`` deep. Walked without recursion, as :func:`_unicode`."""
    pending = [(value, 0)]
    while pending:
        item, depth = pending.pop()
        if isinstance(item, (dict, list)):
            if depth == levels:
                return True
            pending.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return False


def _unicode(value: object) -> bool:
    """Whether every string in ``value`` (a parsed JSON value) encodes as UTF-8. Walked
    without recursion: nested as deeply as the JSON parser takes (found from outside: an id
    of 500 nested arrays), two Python frames a level overflowed the stack of the API's
    thread, which died, and no request was answered again, an E-stop included."""
    pending = [value]
    while pending:
        item = pending.pop()
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                return False
        elif isinstance(item, dict):
            pending.extend(item.keys())
            pending.extend(item.values())
        elif isinstance(item, list):
            pending.extend(item)
    return True


def _first_line(error: BaseException) -> str:
    return (str(error).splitlines() or [type(error).__name__])[0][:200]
