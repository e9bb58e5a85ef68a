"""Telemetry: single frames ``telemetry <json>`` that parse into the model, and
subscribers with CONFLATE get the newest record."""

from __future__ import annotations

import json

import zmq

from hexactl.adapters.api.client import TelemetrySubscriber
from hexactl.adapters.api.messages import Telemetry
from hexactl.adapters.api.telemetry import MAX_SUBSCRIPTION_BYTES, telemetry_message
from hexactl.adapters.api.protocol import TOPIC
from tests.reliability.support import wait_for


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


def test_a_subscription_far_longer_than_the_topic_cuts_its_subscriber_off(service) -> None:
    """Found from outside: the telemetry socket took subscriptions of any length, each held
    in ZeroMQ's subscription tree; one of 300 MB grew the API's process past 4 GB within
    seconds, and its shutdown had to kill it. A subscription longer than
    MAX_SUBSCRIPTION_BYTES now closes its subscriber's connection unread; records still
    reach every other subscriber."""
    context = zmq.Context.instance()
    with context.socket(zmq.SUB) as socket:
        socket.linger = 0
        cut_off = socket.get_monitor_socket(zmq.EVENT_DISCONNECTED)
        try:
            socket.setsockopt(zmq.SUBSCRIBE, TOPIC + b"x" * MAX_SUBSCRIPTION_BYTES)
            socket.setsockopt(zmq.SUBSCRIBE, TOPIC)
            socket.connect(service.telemetry)
            wait_for(lambda: cut_off.poll(0) or socket.poll(0), "the subscriber cut off, or a record")
            assert cut_off.poll(0), "a record came: the subscription was taken"
        finally:
            socket.disable_monitor()
            cut_off.close()
    with TelemetrySubscriber(service.telemetry) as telemetry:
        assert telemetry.receive()["state"]
