"""Telemetry: single frames ``telemetry <json>`` that parse into the model, and
subscribers with CONFLATE get the newest record."""

from __future__ import annotations

import json

import zmq

from hexactl.adapters.api.client import TelemetrySubscriber
from hexactl.adapters.api.messages import Telemetry
from hexactl.adapters.api.telemetry import telemetry_message
from hexactl.adapters.api.protocol import TOPIC


def test_records_are_single_frames_that_parse_into_the_model(service) -> None:
    context = zmq.Context.instance()
    with context.socket(zmq.SUB) as socket:
        socket.linger = 0
        socket.setsockopt(zmq.SUBSCRIBE, b"")
        socket.connect(service.telemetry)
        for _ in range(3):
            assert socket.poll(5000), "no telemetry"
            frames = socket.recv_multipart()
            assert len(frames) == 1 and frames[0].startswith(TOPIC)
            record = Telemetry.model_validate_json(frames[0][len(TOPIC):])
            assert record.calibration_id and record.loop.rate_hz == 500.0


def test_subscriber_follows_state_changes(service) -> None:
    with TelemetrySubscriber(service.telemetry) as telemetry:
        assert telemetry.receive()["state"] == "disabled"
        service.controller.state = "estop"
        for _ in range(100):  # conflated: at most one stale record before the new state shows
            record = telemetry.receive()
            if record["state"] == "estop":
                break
        assert record["faults"][0]["code"] == "estop"


def test_non_finite_values_are_never_published() -> None:
    # A record with NaN is not JSON: the publisher's encoding refuses it (and skips the period).
    try:
        telemetry_message({"t": float("nan")})
    except ValueError:
        return
    raise AssertionError("NaN was encoded")


def test_message_layout() -> None:
    assert json.loads(telemetry_message({"t": 1.0})[len(TOPIC):]) == {"t": 1.0}
