"""Test support: a fake controller behind a real API server and telemetry publisher on
random local ports, and raw sockets to talk to them."""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import zmq

from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.server import ApiServer
from hexactl.adapters.api.telemetry import TelemetryPublisher
from hexactl.adapters.files.geometry_file import geometry_id
from hexactl.control.sequences import MotionSequence
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import PoseAssessment, assess_pose

LOCAL = "tcp://127.0.0.1:*"


@dataclass(frozen=True)
class FakeResult:
    ok: bool = True
    code: str | None = None
    message: str = ""
    details: Any = None


@dataclass
class FakeController:
    """Enough of a controller to exercise every command: a state name, the refusals a
    real one makes (not_enabled, out_of_workspace, estop_active), calls recorded."""

    geometry: Geometry
    state: str = "disabled"
    calls: list[tuple[str, tuple]] = field(default_factory=list)
    previous: list[Geometry] = field(default_factory=list)
    locked_leg: int | None = None
    sequence: MotionSequence | None = None

    def _call(self, name: str, *arguments: Any) -> None:
        self.calls.append((name, arguments))

    def enable(self) -> FakeResult:
        self._call("enable")
        if self.state == "estop":
            return FakeResult(False, "estop_active", "reset first")
        self.state = "enabled"
        return FakeResult(message="enabled")

    def disable(self) -> FakeResult:
        self._call("disable")
        self.state = "disabled"
        return FakeResult()

    def stop(self) -> FakeResult:
        self._call("stop")
        return FakeResult()

    def estop(self) -> FakeResult:
        self._call("estop")
        self.state = "estop"
        return FakeResult()

    def reset(self) -> FakeResult:
        self._call("reset")
        self.state = "disabled"
        return FakeResult()

    def move(self, pose: Sequence[float], duration_s: float | None, speed: float | None) -> FakeResult:
        self._call("move", list(pose), duration_s, speed)
        if self.state != "enabled":
            return FakeResult(False, "not_enabled", "enable first")
        assessment = self.assess(pose)
        if not assessment.ok:
            return FakeResult(False, "out_of_workspace", "refused", list(assessment.violations))
        return FakeResult(message="moving")

    def assess(self, pose: Sequence[float]) -> PoseAssessment:
        return assess_pose(self.geometry, pose)

    def leg_lock(self, leg: int) -> FakeResult:
        self._call("leg_lock", leg)
        self.locked_leg = leg
        return FakeResult()

    def leg_unlock(self) -> FakeResult:
        self._call("leg_unlock")
        self.locked_leg = None
        return FakeResult()

    def play(self, sequence: MotionSequence) -> FakeResult:
        self._call("play", sequence)
        self.sequence = sequence
        return FakeResult()

    def pause(self) -> FakeResult:
        self._call("pause")
        return FakeResult()

    def resume(self) -> FakeResult:
        self._call("resume")
        return FakeResult()

    def abort(self) -> FakeResult:
        self._call("abort")
        self.sequence = None
        return FakeResult()

    def load_calibration(self, geometry: Geometry) -> FakeResult:
        self._call("load_calibration", geometry)
        self.previous.append(self.geometry)
        self.geometry = geometry
        return FakeResult()

    def rollback_calibration(self) -> FakeResult:
        self._call("rollback_calibration")
        if not self.previous:
            return FakeResult(False, "no_previous_calibration", "nothing to roll back to")
        self.geometry = self.previous.pop()
        return FakeResult()

    def telemetry(self) -> dict[str, Any]:
        percentiles = {"p50": 10.0, "p99": 20.0, "p999": 30.0, "max": 40.0}
        return {
            "t": time.time(),
            "state": self.state,
            "pose_command": [0.0] * 6,
            "pose_measured": None,
            "leg_setpoints": [425.0] * 6,
            "leg_feedback": [425.0] * 6,
            "locked_leg": self.locked_leg,
            "calibration_id": geometry_id(self.geometry),
            "sequence": {"name": self.sequence.name, "index": 0, "total": len(self.sequence.waypoints)} if self.sequence else None,
            "faults": [{"code": "estop", "message": "emergency stop", "leg": None}] if self.state == "estop" else [],
            "loop": {"rate_hz": 500.0, "cycles": 1, "missed": 0, "lateness_us": percentiles, "compute_us": percentiles},
        }


def start_service(geometry: Geometry, data_dir: Path, telemetry_rate_hz: float = 200.0) -> SimpleNamespace:
    """A fake controller served on random local ports; ``close()`` when done."""
    context = zmq.Context()
    controller = FakeController(geometry)
    server = ApiServer(context, LOCAL, CommandHandler(controller, DataDirectories([data_dir])))
    publisher = TelemetryPublisher(context, LOCAL, controller.telemetry, telemetry_rate_hz)
    server.start()
    publisher.start()

    def close() -> None:
        server.close()
        publisher.close()
        context.term()

    return SimpleNamespace(
        controller=controller, api=server.endpoint, telemetry=publisher.endpoint, data_dir=data_dir,
        context=context, close=close,
    )


def exchange(endpoint: str, frames: list[bytes], kind: int = zmq.DEALER, timeout_s: float = 5.0) -> list[bytes]:
    """Send ``frames`` from a fresh REQ or DEALER socket; the reply's frames (REQ strips
    the envelope, a DEALER sees what follows it). AssertionError if none arrives."""
    context = zmq.Context.instance()
    with context.socket(kind) as socket:
        socket.linger = 0
        socket.connect(endpoint)
        socket.send_multipart(frames)
        assert socket.poll(timeout_s * 1000), f"no reply to {frames!r:.200}"
        return socket.recv_multipart()


def request(endpoint: str, document: dict[str, Any], kind: int = zmq.DEALER) -> dict[str, Any]:
    """Send one JSON request, return the decoded reply."""
    frames = exchange(endpoint, [json.dumps(document).encode()], kind)
    assert len(frames) == 1
    return json.loads(frames[0])
