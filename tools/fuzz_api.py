#!/usr/bin/env python3
"""Fuzz the command API of a real service: hostile requests, one reply each, the service
keeps serving, the loop keeps its rate, no set-point beyond the limits reaches the bus.

    python tools/fuzz_api.py --count 10000 --fifo 80 --mlock  # the figures in BENCHMARKS.md
    python tools/fuzz_api.py --count 10000                 # normal scheduling
    python tools/fuzz_api.py --count 500 --json fuzz.json  # the CI-sized run (tests/reliability)

The target: ``Service.start`` in a child process on its simulator, enabled, so that the
requests that happen to be valid really move the platform, with a
:class:`~hexactl.adapters.can.bus_monitor.BusMonitor` on the simulator's bus
(:class:`soak.MonitoredService`). Hypothesis generates the requests (generation only: no
shrinking, no example database; ``--seed`` makes a run repeatable), in categories, each
with the outcomes the API documents for it (docs/api.md):

==================  ==================================================================
``random_bytes``    any bytes: an error of the request's syntax
``truncated``       a valid request cut short: ``malformed_json``
``non_finite``      NaN, Infinity or 1e400 where a number goes: ``malformed_json``
``huge``            above 64 KiB (``too_large``), 60 KiB arrays (``invalid_request``),
                    nesting 20 000 deep (``malformed_json``), sequences of the most waypoints
                    allowed (carried out) and one more (``invalid_request``)
``envelope``        ``v``, ``id`` or ``cmd`` missing or wrong, not an object
``unknown_command`` a ``cmd`` that is none: ``unknown_command``
``wrong_type``      one field of a valid request of the wrong type: ``invalid_request``
``out_of_range``    legs outside 1–6, speeds outside (0, 1], negative durations and
                    dwells (``invalid_request``); poses outside the envelope, up to
                    1e300 (``move`` and ``play`` refused, ``validate_pose`` valid=false)
``hostile_files``   paths out of the data directories (``..``, absolute, symlinks out,
                    /proc, a FIFO, a 4 MiB+ file, over-long names), calibration and
                    sequence texts and files that are broken, binary or nested 1000
                    deep, TOML asking for shell or Python: refused
``multipart``       2–4 frames: ``invalid_request`` or ``too_large``
``valid``           every command with valid arguments: ok, or refused for a reason of
                    state or content (never a syntax error); ok replies must match
                    their documented model
==================  ==================================================================

Every reply must come (each request is followed by a ``status`` on the same socket, so a
missing or extra reply shows), be an ``ErrorReply`` or the command's ok model, carry the
request's ``id`` when it could be read (else null), and have an outcome its category
allows. After each request the platform is enabled again if a request disabled,
E-stopped or faulted it (counted by cause).

Prints the requests by category and outcome, the unexpected ones (must be 0), the
replies missing (must be 0), the loop's missed cycles before and after and its achieved
rate, and the monitor's figures (violations must be 0). Exit status 0 when those three
are 0, else 1.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zmq
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter, ValidationError

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from soak import (  # noqa: E402
    MonitoredService,
    Scheduling,
    add_service_arguments,
    calibration_variants,
    conclude,
    loop_difference,
    realtime_line,
    scheduling_from,
)

from hexactl.adapters.api.client import ServiceUnavailable  # noqa: E402
from hexactl.adapters.api.messages import COMMANDS, REPLY_MODELS, ErrorReply, OkReply, Request  # noqa: E402
from hexactl.adapters.api.paths import MAX_FILE_BYTES  # noqa: E402
from hexactl.adapters.api.server import DEFAULT_HANDLER_TIMEOUT_S  # noqa: E402
from hexactl.adapters.api.protocol import MAX_REQUEST_BYTES  # noqa: E402
from hexactl.adapters.api.wire import ErrorCode as ApiCode  # noqa: E402
from hexactl.adapters.files.geometry_file import load_geometry  # noqa: E402
from hexactl.adapters.files.config_path import default_config_path  # noqa: E402
from hexactl.control.planning import MAX_WAYPOINTS  # noqa: E402
from hexactl.kinematics.one_line import is_one_line  # noqa: E402
from hexactl.control.results import ErrorCode as ControlCode  # noqa: E402
from hexactl.control.sequences import BUILTIN_SEQUENCES  # noqa: E402
from hexactl.kinematics.geometry import Geometry  # noqa: E402

REPLY_TIMEOUT_S = DEFAULT_HANDLER_TIMEOUT_S + 30.0
"""The API answers every request or, once its worker has spent DEFAULT_HANDLER_TIMEOUT_S in
one, ends itself: a reply missing after that bound (plus a margin) is a broken promise,
while a shorter wait would measure the machine (a 1000-waypoint ``play`` took over 30 s
beside two CPU-bound processes)."""

SYNTAX = frozenset({ApiCode.MALFORMED_JSON, ApiCode.INVALID_REQUEST, ApiCode.UNKNOWN_COMMAND,
                    ApiCode.UNSUPPORTED_VERSION, ApiCode.TOO_LARGE})
"""Outcomes of requests the API cannot read as a command."""
BUGS = frozenset({ApiCode.INTERNAL_ERROR, ControlCode.INVALID_ARGUMENT, ControlCode.LOOP_FAILED})
"""Never a right answer: a bug, the API letting a malformed request through, the loop dead."""
REFUSED = (frozenset(str(code) for code in (*ApiCode, *ControlCode)) - SYNTAX - BUGS) | {str(ApiCode.TOO_LARGE)}
"""Every documented refusal of a well-formed request, for a reason of state or content
(``too_large`` too: a file may be)."""
CARRIED_OUT = REFUSED | {"ok"}
"""A well-formed request: done, or refused."""

_REQUEST = TypeAdapter(Request)


def _well_formed_alone(cmd: str) -> bool:
    """Whether ``cmd`` needs no field besides the envelope."""
    try:
        _REQUEST.validate_python({"v": 1, "id": 1, "cmd": cmd})
    except ValidationError:
        return False
    return True


NO_ARGUMENT_COMMANDS = tuple(sorted(name for name in COMMANDS if _well_formed_alone(name)))


@dataclass(frozen=True)
class Case:
    """One hostile request: its frames, what may come back, and an extra check of an ok reply."""

    category: str
    frames: tuple[bytes, ...]
    expect: frozenset[str]
    command: str | None = None  # a valid command's name, for its ok reply model
    check: Callable[[dict], str | None] | None = field(default=None, compare=False)


def request_bytes(cmd: str, request_id: Any = 1, **fields: Any) -> bytes:
    return json.dumps({"v": 1, "id": request_id, "cmd": cmd, **fields}).encode()


def expected_id(frames: tuple[bytes, ...]) -> Any:
    """The ``id`` the reply must carry: the request's when it can be read (one frame of at
    most 64 KiB, strict JSON, an object with ``id``), else None (docs/api.md)."""
    if len(frames) != 1 or len(frames[0]) > MAX_REQUEST_BYTES:
        return None
    try:
        document = json.loads(frames[0], parse_constant=_refuse, parse_float=_finite)
    except (ValueError, RecursionError):
        return None
    return document.get("id") if isinstance(document, dict) else None


def _refuse(name: str) -> float:
    raise ValueError(name)


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def judge(case: Case, reply_frames: list[bytes]) -> tuple[str, str | None]:
    """(outcome, problem): the reply's ``ok`` or error code, and what is wrong with it (None: nothing)."""
    try:
        reply = json.loads(reply_frames[-1])
    except ValueError:
        return "unreadable", "the reply is not JSON"
    try:
        if reply.get("ok") is True:
            outcome = "ok"
            REPLY_MODELS.get(case.command or "", OkReply).model_validate(reply)
        else:
            ErrorReply.model_validate(reply)
            outcome = reply["error"]["code"]
    except (ValueError, AttributeError, KeyError, TypeError) as error:
        return "malformed_reply", f"the reply does not match its model: {str(error)[:200]}"
    if outcome not in case.expect:
        return outcome, f"{outcome} is not an outcome of {case.category} (expected one of {sorted(case.expect)})"
    if reply["id"] != expected_id(case.frames):
        return outcome, f"reply id {reply['id']!r:.80} instead of {expected_id(case.frames)!r:.80}"
    if outcome == "ok" and case.check is not None:
        return outcome, case.check(reply)
    return outcome, None


# -- the strategies -------------------------------------------------------------------------

ids = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False, allow_infinity=False),
                st.text(max_size=12), st.lists(st.integers(), max_size=3))
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=10),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3),
    max_leaves=8,
)
not_numbers = st.one_of(st.text(max_size=6), st.booleans(), st.lists(st.integers(), max_size=2),
                        st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
NON_FINITE = ("NaN", "Infinity", "-Infinity", "1e400", "-1e400", "1E999")


class Strategies:
    """The request strategies for ``geometry`` and the files :func:`prepare_files` made."""

    def __init__(self, geometry: Geometry, files: dict[str, Any]) -> None:
        self.geometry = geometry
        self.files = files
        low, high = geometry.limits.pose_min, geometry.limits.pose_max
        self.poses_inside = st.tuples(*(st.floats(0.5 * a, 0.5 * b) for a, b in zip(low, high))).map(list)
        # 20 % beyond at least: leg-lock mode projects a goal up to lock_max_correction_mm (25 mm) onto
        # the locked leg's constraint, which may bring one just beyond back inside (and then it is valid).
        # Out of reach, yet within the ±1e6 any pose may have (beyond, it is malformed: poses_absurd).
        self.poses_outside = st.builds(self._push_out, st.integers(0, 5), st.booleans(), st.floats(1.2, 1e3),
                                       self.poses_inside)
        self.poses_absurd = st.builds(self._push_out, st.integers(0, 5), st.booleans(), st.floats(1e7, 1e300),
                                      self.poses_inside)
        self.paces = st.one_of(st.just({}), st.builds(lambda d: {"duration": d}, st.floats(0.05, 3.0)),
                               st.builds(lambda s: {"speed": s}, st.floats(0.05, 1.0)))
        waypoints = st.lists(st.builds(lambda pose, dwell, pace: {"pose": pose, "dwell": dwell, **pace},
                                       self.poses_inside, st.floats(0.0, 0.3), self.paces), min_size=1, max_size=4)
        self.inline = st.builds(lambda name, wps: {"name": name, "waypoints": wps}, st.text(min_size=1, max_size=20), waypoints)
        self.recording_names = st.text("abcdefghijklmnopqrstuvwxyz0123456789_-", min_size=1, max_size=16).map(
            lambda name: f"fuzz-{name}.csv")

    def _push_out(self, axis: int, above: bool, factor: float, pose: list[float]) -> list[float]:
        """``pose`` with one axis ``factor`` times beyond the envelope's end."""
        limits = self.geometry.limits
        pose[axis] = (limits.pose_max if above else limits.pose_min)[axis] * factor
        return pose

    # -- well-formed requests: (command, fields, expected outcomes, extra check) ---------

    def valid_fields(self) -> st.SearchStrategy[tuple[str, dict, frozenset[str], Callable | None]]:
        files = self.files
        carried = lambda cmd, fields: (cmd, fields, CARRIED_OUT, None)  # noqa: E731
        return st.one_of(
            st.just(("status", {}, frozenset({"ok"}), None)),
            st.sampled_from(NO_ARGUMENT_COMMANDS).map(lambda cmd: carried(cmd, {})),  # status, enable, estop, …
            *[st.builds(lambda pose, pace: carried("move", {"pose": pose, **pace}), self.poses_inside, self.paces)] * 4,
            st.builds(lambda pose, pace: ("validate_pose", {"pose": pose, **pace}, frozenset({"ok"}), None),
                      self.poses_inside, self.paces),
            st.integers(1, 6).map(lambda leg: carried("leg_lock", {"leg": leg})),
            st.one_of(st.sampled_from(BUILTIN_SEQUENCES), self.inline,
                      st.sampled_from([files["sequence_good"], files["sequence_bad"]])).map(
                lambda sequence: carried("play", {"sequence": sequence})),
            st.one_of(st.sampled_from(files["calibration_texts"]).map(lambda text: {"toml": text}),
                      st.sampled_from([files["calibration_good"], files["calibration_bad"]]).map(lambda p: {"path": p})).map(
                lambda fields: carried("load_calibration", fields)),
            st.one_of(self.recording_names, st.just(files["recording_taken"])).map(
                lambda path: carried("save_recording", {"path": path})),
        )

    def valid(self) -> st.SearchStrategy[Case]:
        return st.builds(lambda drawn, request_id: Case("valid", (request_bytes(drawn[0], request_id, **drawn[1]),),
                                                        drawn[2], drawn[0], drawn[3]),
                         self.valid_fields(), ids)

    # -- hostile requests ----------------------------------------------------------------

    def random_bytes(self) -> st.SearchStrategy[Case]:
        return st.binary(max_size=300).map(lambda body: Case("random_bytes", (body,), SYNTAX))

    def truncated(self) -> st.SearchStrategy[Case]:
        def cut(drawn: tuple, fraction: float) -> Case:
            body = request_bytes(drawn[0], 7, **drawn[1])
            return Case("truncated", (body[: max(1, min(len(body) - 1, int(len(body) * fraction)))],),
                        frozenset({ApiCode.MALFORMED_JSON}))
        return st.builds(cut, self.valid_fields(), st.floats(0.0, 1.0))

    def non_finite(self) -> st.SearchStrategy[Case]:
        def splice(pose: list[float], index: int, token: str, where: str) -> Case:
            numbers = [json.dumps(value) for value in pose]
            if where == "pose":
                numbers[index] = token
            text = f'{{"v": 1, "id": {token if where == "id" else 3}, "cmd": "move", "pose": [{", ".join(numbers)}]'
            text += f', "duration": {token}}}' if where == "duration" else "}"
            return Case("non_finite", (text.encode(),), frozenset({ApiCode.MALFORMED_JSON}))
        return st.builds(splice, self.poses_inside, st.integers(0, 5), st.sampled_from(NON_FINITE),
                         st.sampled_from(["pose", "id", "duration"]))

    def huge(self) -> st.SearchStrategy[Case]:
        padded = st.integers(MAX_REQUEST_BYTES + 1, 3 * MAX_REQUEST_BYTES).map(
            lambda size: Case("huge", (request_bytes("status", 1, pad="x" * size),), frozenset({ApiCode.TOO_LARGE})))
        long_pose = st.integers(2000, 9000).map(
            lambda n: Case("huge", (request_bytes("move", 1, pose=[1.5] * n),), frozenset({ApiCode.INVALID_REQUEST})))
        nested = st.tuples(st.integers(20_000, 60_000), st.sampled_from(["[", '{"a":'])).map(
            lambda drawn: Case("huge", ((drawn[1] * (drawn[0] // len(drawn[1]))).encode(),),
                               frozenset({ApiCode.MALFORMED_JSON})))
        long_sequence = st.integers(0, 2**32).map(  # drawn from a seed: 500 poses overrun hypothesis's buffer
            lambda value: Case("huge", (request_bytes("play", 1, sequence={"name": "long", "waypoints": [
                {"pose": pose} for pose in self._random_poses(random.Random(value), MAX_WAYPOINTS)]}),),
                CARRIED_OUT, "play"))
        too_long_sequence = st.integers(0, 2**32).map(
            lambda value: Case("huge", (request_bytes("play", 1, sequence={"name": "too long", "waypoints": [
                {"pose": pose} for pose in self._random_poses(random.Random(value), MAX_WAYPOINTS + 1)]}),),
                frozenset({ApiCode.INVALID_REQUEST})))
        return st.one_of(padded, long_pose, nested, long_sequence, too_long_sequence)

    def _random_poses(self, rng: random.Random, count: int) -> list[list[float]]:
        low, high = self.geometry.limits.pose_min, self.geometry.limits.pose_max
        return [[round(rng.uniform(0.5 * a, 0.5 * b), 1) for a, b in zip(low, high)] for _ in range(count)]

    def envelope(self) -> st.SearchStrategy[Case]:
        no_id = st.just(Case("envelope", (b'{"v": 1, "cmd": "status"}',), frozenset({ApiCode.INVALID_REQUEST})))
        no_v = ids.map(lambda i: Case("envelope", (json.dumps({"id": i, "cmd": "status"}).encode(),),
                                      frozenset({ApiCode.INVALID_REQUEST})))
        bad_v = st.tuples(ids, st.one_of(st.integers().filter(lambda v: v != 1), st.just(1.0), st.just("1"),
                                          st.booleans(), st.none(), st.lists(st.integers(), max_size=2))).map(
            lambda drawn: Case("envelope", (json.dumps({"v": drawn[1], "id": drawn[0], "cmd": "status"}).encode(),),
                               frozenset({ApiCode.UNSUPPORTED_VERSION})))
        bad_cmd = st.tuples(ids, st.one_of(st.none(), st.integers(), st.booleans(), st.lists(st.text(max_size=3), max_size=2))).map(
            lambda drawn: Case("envelope", (json.dumps({"v": 1, "id": drawn[0], "cmd": drawn[1]}).encode(),),
                               frozenset({ApiCode.INVALID_REQUEST})))
        no_cmd = ids.map(lambda i: Case("envelope", (json.dumps({"v": 1, "id": i}).encode(),),
                                        frozenset({ApiCode.INVALID_REQUEST})))
        not_object = json_values.filter(lambda value: not isinstance(value, dict)).map(
            lambda value: Case("envelope", (json.dumps(value).encode(),), frozenset({ApiCode.INVALID_REQUEST})))
        return st.one_of(no_id, no_v, bad_v, bad_cmd, no_cmd, not_object)

    def unknown_command(self) -> st.SearchStrategy[Case]:
        names = st.one_of(st.text(max_size=30), st.sampled_from(COMMANDS).map(str.upper),
                          st.sampled_from(COMMANDS).map(lambda c: f" {c}"), st.sampled_from(COMMANDS).map(lambda c: c + "\0"))
        return st.tuples(ids, names.filter(lambda name: name not in COMMANDS)).map(
            lambda drawn: Case("unknown_command", (request_bytes(drawn[1], drawn[0]),), frozenset({ApiCode.UNKNOWN_COMMAND})))

    def wrong_type(self) -> st.SearchStrategy[Case]:
        wrong_pose = st.one_of(not_numbers, st.none(), st.integers(),
                               st.lists(st.floats(-100, 100), max_size=5), st.lists(st.floats(-100, 100), min_size=7, max_size=12),
                               st.tuples(self.poses_inside, st.integers(0, 5), st.one_of(not_numbers, st.none())).map(
                                   lambda drawn: [*drawn[0][:drawn[1]], drawn[2], *drawn[0][drawn[1] + 1:]]))
        wrong_leg = st.one_of(st.floats(1, 6), st.booleans(), st.text(max_size=3), st.none(), st.lists(st.integers(1, 6), max_size=2))
        wrong_sequence = st.one_of(st.integers(), st.floats(allow_nan=False, allow_infinity=False), st.booleans(), st.none(),
                                   st.lists(st.text(max_size=3), max_size=2), st.just({"name": "x"}),
                                   st.just({"name": "x", "waypoints": []}), st.just({"waypoints": [{"pose": [0] * 6}]}),
                                   st.just({"name": "x", "waypoints": [{"pose": [0] * 6}], "loop": True}))
        wrong_text = st.one_of(st.integers(), st.booleans(), st.lists(st.text(max_size=3), max_size=2),
                               st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
        cases = st.one_of(
            st.tuples(st.sampled_from(["move", "validate_pose"]), self.poses_inside,
                      st.sampled_from(["pose", "duration", "speed"]), wrong_pose, not_numbers).map(
                lambda d: (d[0], {"pose": d[1], d[2]: d[3] if d[2] == "pose" else d[4]})),
            wrong_leg.map(lambda value: ("leg_lock", {"leg": value})),
            wrong_sequence.map(lambda value: ("play", {"sequence": value})),
            st.one_of(wrong_text.map(lambda value: {"path": value}), wrong_text.map(lambda value: {"toml": value}),
                      st.just({}), st.just({"path": "a.toml", "toml": ""}), st.just({"path": ""})).map(
                lambda fields: ("load_calibration", fields)),
            st.one_of(wrong_text, st.just("")).map(lambda value: ("save_recording", {"path": value})),
            st.tuples(st.sampled_from(COMMANDS), st.text(max_size=8), json_values).map(
                lambda d: (d[0], {**self._minimal(d[0]), f"x_{d[1]}": d[2]})),  # an unknown field
            st.tuples(self.poses_inside, st.floats(0.1, 2.0), st.floats(0.1, 1.0)).map(
                lambda d: ("move", {"pose": d[0], "duration": d[1], "speed": d[2]})),
        )
        return st.tuples(cases, ids).map(lambda d: Case("wrong_type", (request_bytes(d[0][0], d[1], **d[0][1]),),
                                                         frozenset({ApiCode.INVALID_REQUEST})))

    @staticmethod
    def _minimal(cmd: str) -> dict[str, Any]:
        """The fields that make ``cmd`` well formed."""
        return {"move": {"pose": [0] * 6}, "validate_pose": {"pose": [0] * 6}, "leg_lock": {"leg": 1},
                "play": {"sequence": "x_sweep"}, "load_calibration": {"toml": ""},
                "save_recording": {"path": "r.csv"}}.get(cmd, {})

    def out_of_range(self) -> st.SearchStrategy[Case]:
        invalid = frozenset({ApiCode.INVALID_REQUEST})
        fields = st.one_of(
            st.one_of(st.integers(max_value=0), st.integers(min_value=7)).map(lambda leg: ("leg_lock", {"leg": leg}, invalid)),
            st.tuples(self.poses_inside, st.one_of(st.floats(max_value=0.0, allow_nan=False, allow_infinity=False),
                                                   st.floats(min_value=1.0, exclude_min=True, allow_nan=False,
                                                             allow_infinity=False))).map(
                lambda d: ("move", {"pose": d[0], "speed": d[1]}, invalid)),
            st.tuples(self.poses_inside, st.floats(max_value=0.0, allow_nan=False, allow_infinity=False)).map(
                lambda d: ("validate_pose", {"pose": d[0], "duration": d[1]}, invalid)),
            st.tuples(self.poses_inside, st.floats(max_value=-1e-9, allow_nan=False, allow_infinity=False)).map(
                lambda d: ("play", {"sequence": {"name": "n", "waypoints": [{"pose": d[0], "dwell": d[1]}]}}, invalid)),
            self.poses_outside.map(lambda pose: ("move", {"pose": pose}, REFUSED)),
            self.poses_outside.map(lambda pose: ("play", {"sequence": {"name": "out", "waypoints": [{"pose": pose}]}},
                                                 REFUSED)),
            self.poses_outside.map(lambda pose: ("validate_pose", {"pose": pose}, frozenset({"ok"}))),
            st.tuples(self.poses_absurd, st.sampled_from(["move", "validate_pose", "play"])).map(
                lambda d: (d[1], {"sequence": {"name": "absurd", "waypoints": [{"pose": d[0]}]}} if d[1] == "play"
                           else {"pose": d[0]}, invalid)),
        )

        def case(drawn: tuple, request_id: Any) -> Case:
            cmd, values, expect = drawn
            check = _not_valid if cmd == "validate_pose" and expect == frozenset({"ok"}) else None
            return Case("out_of_range", (request_bytes(cmd, request_id, **values),), expect, cmd, check)

        return st.builds(case, fields, ids)

    def hostile_files(self) -> st.SearchStrategy[Case]:
        files = self.files
        reads = st.sampled_from(files["hostile_reads"])
        writes = st.sampled_from(files["hostile_writes"])
        texts = st.sampled_from(files["hostile_texts"])
        broken = st.sampled_from(files["broken_files"])
        return st.one_of(
            reads.map(lambda p: ("load_calibration", {"path": p}, read_refusals(p))),
            reads.map(lambda p: ("play", {"sequence": p if p.endswith(".toml") else p + ".toml"}, read_refusals(p))),
            writes.map(lambda p: ("save_recording", {"path": p}, save_refusals(p))),
            texts.map(lambda text: ("load_calibration", {"toml": text}, frozenset({ApiCode.INVALID_CALIBRATION}))),
            broken.map(lambda p: ("load_calibration", {"path": p}, frozenset({ApiCode.INVALID_CALIBRATION}))),
            broken.map(lambda p: ("play", {"sequence": p}, frozenset({ApiCode.INVALID_SEQUENCE}))),
        ).map(lambda d: Case("hostile_files", (request_bytes(d[0], 5, **d[1]),), d[2], d[0]))

    def multipart(self) -> st.SearchStrategy[Case]:
        frame = st.one_of(st.binary(min_size=1, max_size=100), st.just(request_bytes("status")),
                          st.just(b"x" * (MAX_REQUEST_BYTES // 2 + 1)))
        return st.lists(frame, min_size=2, max_size=4).map(
            lambda frames: Case("multipart", tuple(frames), frozenset({ApiCode.INVALID_REQUEST, ApiCode.TOO_LARGE})))

    def cases(self) -> st.SearchStrategy[Case]:
        """Every category; valid requests three times as often as each hostile one."""
        return st.one_of(self.valid(), self.valid(), self.valid(), self.random_bytes(), self.truncated(),
                         self.non_finite(), self.huge(), self.envelope(), self.unknown_command(), self.wrong_type(),
                         self.out_of_range(), self.hostile_files(), self.multipart())


NAME_MAX_BYTES = 255
"""The longest file name Linux's file systems take (a directory entry's)."""


def read_refusals(path: str) -> frozenset[str]:
    """How the service refuses to read a hostile ``path``: outside the data directories, not
    there or not a regular file, too large; a path that is not one line of text (a line end,
    a NUL) is no name a request takes (``invalid_request``)."""
    if not is_one_line(path):
        return frozenset({ApiCode.INVALID_REQUEST})
    return frozenset({ApiCode.FORBIDDEN_PATH, ApiCode.FILE_NOT_FOUND, ApiCode.TOO_LARGE})


def save_refusals(path: str) -> frozenset[str]:
    """How the service may refuse ``save_recording`` to a hostile ``path``: outside the data
    directories or not there, or nothing recorded yet; a name too long for the file system
    is refused only once there is a recording to write (``write_failed``, "give a shorter
    name"), which depends on what the run played before."""
    if not is_one_line(path):
        return frozenset({ApiCode.INVALID_REQUEST})
    refusals = {ApiCode.FORBIDDEN_PATH, ApiCode.FILE_NOT_FOUND, ApiCode.FILE_EXISTS, ApiCode.NO_RECORDING}
    if Path(path).suffix.lower() != ".csv":  # a recording is named as CSV, whatever else is wrong with the path
        refusals.add(ApiCode.INVALID_REQUEST)
    if len(Path(path).name.encode()) > NAME_MAX_BYTES:
        refusals.add(ApiCode.WRITE_FAILED)
    return frozenset(refusals)


def _not_valid(reply: dict) -> str | None:
    return None if reply.get("valid") is False else "validate_pose called a pose outside the envelope valid"


# -- the target's files ---------------------------------------------------------------------


def prepare_files(root: Path, geometry: Geometry) -> dict[str, Any]:
    """The data directory (``root/data``) with good and bad calibration and sequence
    files, and hostile paths out of it (``root/outside`` holds a valid calibration, so
    that reading it would show as an accepted one)."""
    data, outside = root / "data", root / "outside"
    # What a calibration text asks a shell to create; it must never appear. In this run's own
    # directory: a fixed /tmp name left by one run, or made by another, was every run's finding.
    pwned = root / "pwned"
    data.mkdir()
    outside.mkdir()
    good_texts = calibration_variants(geometry, seed=1, count=4)
    (data / "cal_good.toml").write_text(good_texts[0])
    (data / "cal_bad.toml").write_text("zero_lengths = [1, 2, 3]\n")
    (data / "seq_good.toml").write_text('name = "file"\n[[waypoint]]\npose = [0, 0, 20, 0, 0, 0]\ndwell = 0.1\n'
                                        '[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\n')
    (data / "seq_bad.toml").write_text('name = 3\n[[waypoint]]\npose = [0, 0]\n')
    nested = "x = " + "[" * 1000 + "]" * 1000  # deeper than Python's recursion limit
    (data / "nested.toml").write_text(f'name = "nested"\n{nested}\n')
    (data / "binary.toml").write_bytes(b"\xff\xfe\x00garbage")
    (outside / "canary.toml").write_text(good_texts[1])
    (data / "link_out.toml").symlink_to(outside / "canary.toml")
    (data / "link_out.csv").symlink_to(outside / "escaped_by_link.csv")  # a write through it would escape
    (data / "taken.csv").write_text("a recording saved before\n")
    (data / "linkdir").symlink_to(outside)
    os.mkfifo(data / "fifo.toml")  # reading it would block the API thread forever
    with (data / "big.toml").open("wb") as big:
        big.truncate(MAX_FILE_BYTES + 1)  # sparse: above the limit without the disk
    hostile_reads = [  # each one either out of the data directory, or in it and not a readable regular file
        "../outside/canary.toml", "link_out.toml", "linkdir/canary.toml", str(outside / "canary.toml"),
        "/etc/passwd", "/proc/self/environ", "/dev/zero", "fifo.toml", "big.toml", "~/canary.toml",
        "$HOME/canary.toml", "file:///etc/passwd", "..\\..\\canary.toml", "%2e%2e/outside/canary.toml",
        "canary.toml\n", "．．/outside/canary.toml", "a" * 300 + ".toml", "x/" * 1000 + "y.toml", "linkdir", "/",
    ]
    hostile_writes = [  # out of the data directory (into ``outside``, where an escape would show), or refused in it
        "../outside/escaped.csv", "linkdir/escaped.csv", str(outside / "escaped.csv"), "../escaped.csv",
        "link_out.toml", "linkdir", ".", "..", "a" * 300 + ".csv", "a" * 300 + "/r.csv", "x/" * 1000 + "r.csv",
        "missing/r.csv", "link_out.csv",
    ]
    hostile_texts = [
        nested, "[[a]]\n" * 5000, "zero_lengths = [nan, 1, 2, 3, 4, 5]\n", "include = '/etc/passwd'\n",
        good_texts[2].replace('name = "', f'name = "$(touch \'{pwned}\') ') + "\n[extra]\ncode = '__import__(\"os\")'\n",
        "\0\0\0", "a = 1\na = 2\n", 'x = """' + "y" * 1000,
    ]
    return {
        "data": data, "outside": outside, "pwned": pwned,
        "calibration_good": "cal_good.toml", "calibration_bad": "cal_bad.toml",
        "calibration_texts": good_texts[2:] + ["not toml"],
        "sequence_good": "seq_good.toml", "sequence_bad": "seq_bad.toml", "recording_taken": "taken.csv",
        "broken_files": ["nested.toml", "binary.toml", "cal_bad.toml", "seq_bad.toml"],
        "hostile_reads": hostile_reads, "hostile_writes": hostile_writes, "hostile_texts": hostile_texts,
    }


# -- the run --------------------------------------------------------------------------------


class Fuzzer:
    """Sends cases to the service, each followed by a ``status``, and tallies the outcomes."""

    def __init__(self, harness: MonitoredService) -> None:
        self.harness = harness
        self.context = zmq.Context()
        self.socket = self._connect()
        self.outcomes: Counter[tuple[str, str]] = Counter()
        self.unexpected: list[dict[str, Any]] = []
        self.missing = 0
        self.extra = 0
        self.slowest: tuple[float, str] = (0.0, "")
        self.sent = 0

    def _connect(self) -> zmq.Socket:
        socket = self.context.socket(zmq.DEALER)
        socket.linger = 0
        socket.connect(self.harness.api_endpoint)
        return socket

    def close(self) -> None:
        self.socket.close()
        self.context.term()

    def send(self, case: Case) -> None:
        self.sent += 1
        marker = f"marker-{self.sent}"
        started = time.monotonic()
        self.socket.send_multipart(list(case.frames))
        self.socket.send(request_bytes("status", marker))
        replies: list[list[bytes]] = []
        while True:
            if not self.socket.poll(REPLY_TIMEOUT_S * 1000):
                self.missing += 1
                self._note(case, "no_reply", f"no reply within {REPLY_TIMEOUT_S:g} s")
                self.socket.close()
                self.socket = self._connect()  # late replies must not be taken for the next case's
                return
            frames = self.socket.recv_multipart()
            if _reply_id(frames) == marker:
                break
            replies.append(frames)
        self.slowest = max(self.slowest, (time.monotonic() - started, case.category))
        if not replies:
            self.missing += 1
            self._note(case, "no_reply", "the status after it was answered first")
            return
        if len(replies) > 1:
            self.extra += len(replies) - 1
            self._note(case, "extra_reply", f"{len(replies)} replies")
        outcome, problem = judge(case, replies[0])
        self.outcomes[(case.category, outcome)] += 1
        if problem:
            self._note(case, outcome, problem)
        if json.loads(frames[-1]).get("status", {}).get("state") != "enabled":
            self.harness.ensure_enabled()

    def _note(self, case: Case, outcome: str, problem: str) -> None:
        if len(self.unexpected) < 1000:
            shown = [frame[:300].decode("utf-8", "replace") for frame in case.frames]
            self.unexpected.append({"category": case.category, "outcome": outcome, "problem": problem, "request": shown})


def _serving(harness: MonitoredService) -> bool:
    try:
        return harness.status()["state"] is not None
    except ServiceUnavailable:
        return False


def _reply_id(frames: list[bytes]) -> Any:
    try:
        return json.loads(frames[-1]).get("id")
    except (ValueError, AttributeError):
        return None


def fuzz(count: int, seed_value: int, rate_hz: int = 500, scheduling: Scheduling = Scheduling()) -> dict[str, Any]:
    """Run ``count`` cases against a fresh monitored service; the figures."""
    with tempfile.TemporaryDirectory(prefix="hexactl-fuzz-") as directory:
        root = Path(directory)
        files = prepare_files(root, load_geometry(default_config_path()))
        with MonitoredService(files["data"], rate_hz, scheduling=scheduling) as harness:
            strategies = Strategies(harness.geometry, files)
            fuzzer = Fuzzer(harness)
            try:
                harness.ensure_enabled()
                harness.recoveries.clear()
                harness.recovery_reasons.clear()
                before = harness.loop_figures()
                started = time.monotonic()
                run = seed_value
                while fuzzer.sent < count:  # hypothesis may stop a run early; another seed continues
                    remaining = count - fuzzer.sent

                    @seed(run)
                    @settings(max_examples=remaining, phases=[Phase.generate], database=None, deadline=None,
                              suppress_health_check=list(HealthCheck))
                    @given(case=strategies.cases())
                    def one(case: Case) -> None:
                        if fuzzer.sent < count:
                            fuzzer.send(case)

                    one()
                    run += 1
                elapsed = time.monotonic() - started
                after = harness.loop_figures()
                serving = _serving(harness)
            finally:
                fuzzer.close()
            outcomes: dict[str, dict[str, int]] = {}
            for (category, outcome), number in sorted(fuzzer.outcomes.items()):
                outcomes.setdefault(category, {})[outcome] = number
            by_outcome = Counter()
            for (_, outcome), number in fuzzer.outcomes.items():
                by_outcome[outcome] += number
            escaped = sorted(str(path.relative_to(root)) for path in files["outside"].rglob("*")
                             if path.name != "canary.toml")
            return {
                "requests": fuzzer.sent,
                "seconds": round(elapsed, 1),
                "seed": seed_value,
                "rate_hz": rate_hz,
                "realtime": harness.realtime,
                "by_category": outcomes,
                "by_outcome": dict(by_outcome.most_common()),
                "unexpected": len(fuzzer.unexpected),
                "unexpected_examples": fuzzer.unexpected[:20],
                "replies_missing": fuzzer.missing,
                "extra_replies": fuzzer.extra,
                "slowest_reply_s": round(fuzzer.slowest[0], 3),
                "slowest_category": fuzzer.slowest[1],
                "still_serving": serving,
                "code_executed": files["pwned"].exists(),
                "files_escaped": escaped,
                "recoveries": dict(harness.recoveries),
                "recovery_reasons": dict(harness.recovery_reasons.most_common()),
                "loop": loop_difference(before, after),
                "monitor": harness.monitor_figures(),
            }


def passed(result: dict[str, Any]) -> bool:
    return (result["unexpected"] == 0 and result["replies_missing"] == 0 and result["extra_replies"] == 0
            and result["monitor"]["violations"] == 0 and result["still_serving"] and not result["code_executed"]
            and not result["files_escaped"])


def print_report(result: dict[str, Any]) -> None:
    loop, monitor = result["loop"], result["monitor"]
    print(f"fuzz: {result['requests']} requests in {result['seconds']} s (seed {result['seed']}) at "
          f"{result['rate_hz']} Hz; {realtime_line(result['realtime'])}")
    print("  outcomes by error code:")
    for outcome, number in result["by_outcome"].items():
        print(f"    {outcome:30s} {number}")
    print("  by category:")
    for category, outcomes in result["by_category"].items():
        print(f"    {category:16s} " + ", ".join(f"{outcome} {number}" for outcome, number in outcomes.items()))
    print(f"  unexpected outcomes: {result['unexpected']}; replies missing: {result['replies_missing']}; "
          f"extra replies: {result['extra_replies']}; slowest reply {result['slowest_reply_s']} s ({result['slowest_category']})")
    for example in result["unexpected_examples"]:
        print(f"    [{example['category']}] {example['problem']}: {example['request']!r:.300}")
    print(f"  platform re-enabled after: {result['recoveries'] or 'nothing'}; code executed: {result['code_executed']}; "
          f"files written outside the data directory: {result['files_escaped'] or 'none'}")
    print(f"  loop: missed {loop['missed_before']} before, {loop['missed_after']} after ({loop['missed']} during, "
          f"skipped {loop['skipped']}); {loop['cycles']} cycles at {loop['achieved_rate_hz']} Hz achieved; "
          f"lateness max {loop['lateness_us']['max']:.0f} us; guard clamps {loop['guard_clamps']}")
    print(f"  monitor: {monitor['violations']} violations; {monitor['counts'].get('setpoints', 0)} set-points in "
          f"{monitor['counts'].get('cycles', 0)} cycles checked, {monitor['counts'].get('starts', 0)} leg starts, "
          f"largest step {monitor['max_step_fraction']:.3f} of the limit, closest to a stroke end "
          f"{monitor['min_stroke_margin_mm']} mm")
    for line in monitor["first_violations"]:
        print(f"    {line}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=10_000, help="hostile requests to send")
    add_service_arguments(parser)
    arguments = parser.parse_args(argv)
    result = fuzz(arguments.count, arguments.seed, arguments.rate, scheduling_from(arguments))
    return conclude(result, arguments, print_report, passed)


if __name__ == "__main__":
    sys.exit(main())
