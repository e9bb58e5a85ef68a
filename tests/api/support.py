"""Test support: a fake controller behind a real API server and telemetry publisher on
random local ports, and raw sockets to talk to them."""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Collection, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import zmq

from hexactl.adapters.api.commands import CommandHandler, Instrument
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.server import ApiServer
from hexactl.adapters.api.telemetry import TelemetryPublisher
from hexactl.adapters.api.wire import jsonable
from hexactl.adapters.files.geometry_file import geometry_id
from hexactl.application.service import Service, ServiceConfig, fifo_below_loop
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.snapshot import Event
from hexactl.control.telemetry import EventLog, SequenceTelemetry, Telemetry, events_after
from hexactl.control.sequence_player import SequenceReport
from hexactl.control.supervisor import Fault
from hexactl.control.planning import ActiveGeometry
from hexactl.control.stream_commands import TargetResult
from hexactl.control.results import CommandResult, ErrorCode
from hexactl.control.sequences import DwellRecord, MotionSequence
from hexactl.control.stats import LoopStats, Percentiles
from hexactl.control.validated_under import ValidatedUnder
from hexactl.control.waves import WaveSpec
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import assess_pose

LOCAL = "tcp://127.0.0.1:*"


RECORDS = (
    DwellRecord("steps", 1, 10.0, (0.0, 0.0, 10.0, 0.0, 0.0, 0.0), None, (400.0,) * 6, (400.1,) * 6),
    DwellRecord("steps", 2, 12.5, (0.0,) * 6, (0.01, 0.0, 0.02, 0.0, 0.0, 0.0), (390.0,) * 6, (390.1,) * 6),
)


def wave_figures(spec: WaveSpec) -> dict[str, Any]:
    """Made-up figures of a wave, in the controller's details."""
    return {"duration_s": spec.duration_s, "cycles": spec.cycles, "samples": 500 * spec.cycles,
            "peak_leg_speed_mm_s": 12.5, "peak_leg_speed_leg": 2, "peak_leg_acceleration_mm_s2": 80.0,
            "peak_leg_acceleration_leg": 2, "peak_pose_velocity": [0.0, 0.0, 12.5, 0.0, 0.0, 0.0]}


class FakeStreamInput:
    """A stream receiver's endpoints and an empty view."""

    endpoints = {"zmq": "tcp://127.0.0.1:5557", "udp": None}
    running = True

    def view(self) -> dict[str, Any]:
        return {"running": self.running, "stream": None, "received": 0, "malformed": 0, "out_of_order": 0,
                "other_sender": 0, "no_stream": 0, "coalesced": 0, "forwarded": 0, "clamped": 0, "loop_behind": 0, "failed": 0,
                "last_problem": "",
                "rate_hz": 0, "loop_latency_ms": None, "age_ms": None}


@dataclass
class FakeController:
    """Enough of a controller to exercise every command: a state name, the refusals the
    real one makes (not_enabled, latched, path_violation), calls recorded."""

    geometry: Geometry
    state: str = "disabled"
    calls: list[tuple[str, tuple]] = field(default_factory=list)
    calibrations: list[str] = field(default_factory=list)
    locked_leg: int | None = None
    sequence: MotionSequence | None = None
    frames: OperatorFrames = field(default_factory=OperatorFrames)
    frames_of_moves: list[tuple[Frame, bool]] = field(default_factory=list)
    kept_events: tuple[Event, ...] = ()
    outside_soft_limits: tuple[str, ...] = ()

    def _call(self, name: str, *arguments: Any) -> None:
        self.calls.append((name, arguments))

    def enable(self, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("enable")
        if self.state == "estop":
            return CommandResult.failure(ErrorCode.LATCHED, "ESTOP is latched: reset first")
        self.state = "enabled"
        return CommandResult.success("enabled", ticket=1)

    def disable(self) -> CommandResult:
        self._call("disable")
        self.state = "disabled"
        return CommandResult.success("disabled")

    def stop(self) -> CommandResult:
        self._call("stop")
        return CommandResult.success("stopping")

    def estop(self) -> CommandResult:
        self._call("estop")
        self.state = "estop"
        return CommandResult.success("E-stop latched")

    def reset(self) -> CommandResult:
        self._call("reset")
        self.state = "disabled"
        return CommandResult.success("reset to disabled")

    def move(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
             frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
             validated_under: ValidatedUnder | None = None, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("move", list(pose), duration, speed)
        self.frames_of_moves.append((frame, relative))
        if self.state != "enabled":
            return CommandResult.failure(ErrorCode.NOT_ENABLED, "enable first")
        return self.validate_pose(pose, duration, speed)

    def set_frames(self, frames: OperatorFrames) -> CommandResult:
        self._call("set_frames", frames)
        self.frames = frames
        return CommandResult.success("frames set")

    def operator_frames(self) -> OperatorFrames:
        return self.frames

    accuracy: dict | None = None  # what the fake predicts everywhere (None: no covariance, as the nominal)

    def predicted_accuracy(self) -> dict | None:
        return self.accuracy

    def validate_pose(self, pose: Sequence[float], duration: float | None = None, speed: float | None = None,
                      frame: Frame = Frame.ZERO, relative: bool = False, tolerance_mm: float | None = None,
                      validated_under: ValidatedUnder | None = None) -> CommandResult:
        violations = assess_pose(self.geometry, pose).violations
        if violations:
            items = [{"waypoint": 1, "pose": tuple(pose), **{k: getattr(v, k) for k in ("kind", "message", "value", "limit", "leg", "axis")}}
                     for v in violations]
            return CommandResult.failure(ErrorCode.PATH_VIOLATION, violations[0].message, violations=items)
        return CommandResult.success("valid", goal=list(pose), duration_s=duration or 1.25, waypoints=1,
                                     predicted_accuracy=self.accuracy)

    def jog(self, velocity: Sequence[float], frame: Frame = Frame.ZERO, *, renews: int | None = None,
            restarts: int | None = None, deadline_ns: int | None = None) -> CommandResult:
        self._call("jog", list(velocity), frame)
        return CommandResult.success("jogging", jog=1, goal=[5.0, 0, 0, 0, 0, 0], speed=1.0,
                                     end="the soft limit on x at 5 mm", to_limit=True, deadman_s=0.2)

    def stream_open(self, source: str, frame: Frame | str = Frame.ZERO, timeout_s: float = 0.1, *,
                    deadline_ns: int | None = None) -> CommandResult:
        self._call("stream_open", source, frame, timeout_s)
        if self.state != "enabled":
            return CommandResult.failure(ErrorCode.NOT_ENABLED, "the controller is disabled: enable first")
        return CommandResult.success("stream open", stream=3, velocity_scale=0.5)

    def stream_close(self) -> CommandResult:
        self._call("stream_close")
        return CommandResult.success("stream closed: braking to rest")

    def stream_target(self, pose: Sequence[float], sequence: int, sent_s: float, received_ns: int,
                      before: tuple[Sequence[float], float] | None = None) -> TargetResult:
        self._call("stream_target", list(pose), sequence, sent_s)
        return TargetResult(True)

    def leg_lock(self, leg: int, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("leg_lock", leg)
        self.locked_leg = leg
        return CommandResult.success(f"leg {leg} locked")

    def leg_unlock(self, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("leg_unlock")
        self.locked_leg = None
        return CommandResult.success("unlocked")

    def wave(self, spec: WaveSpec, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("wave", spec)
        if self.state != "enabled":
            return CommandResult.failure(ErrorCode.NOT_ENABLED, "the controller is disabled: enable first")
        return CommandResult.success("waving", **wave_figures(spec))

    def validate_wave(self, spec: WaveSpec) -> CommandResult:
        if spec.axes.get("z") and spec.axes["z"].amplitude > 100:
            return CommandResult.failure(ErrorCode.PLANNING_FAILED, "leg 2 would move at 999.0 mm/s, beyond the legs' "
                                         "speed limit 360 mm/s", kind="leg_speed", leg=2)
        return CommandResult.success("valid", **wave_figures(spec))

    def validate_sequence(self, sequence: MotionSequence) -> CommandResult:
        if len(sequence.waypoints) > 3:
            return CommandResult.failure(ErrorCode.PATH_VIOLATION, "waypoint 4: leg 2 beyond its stroke", waypoint=4)
        return CommandResult.success("valid", duration_s=12.5, waypoints=len(sequence.waypoints),
                                     goal=list(sequence.waypoints[-1].pose))

    def play(self, sequence: MotionSequence, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("play", sequence)
        self.sequence = sequence
        return CommandResult.success(f"playing {sequence.name}", duration_s=12.5, waypoints=len(sequence.waypoints))

    def pause(self) -> CommandResult:
        self._call("pause")
        return CommandResult.success("pausing")

    def resume(self, *, deadline_ns: int | None = None) -> CommandResult:
        self._call("resume")
        return CommandResult.success("resumed")

    def abort(self) -> CommandResult:
        self._call("abort")
        return CommandResult.success("aborted")

    def load_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        self._call("load_calibration", geometry, calibration_id, source)
        self.calibrations.append(calibration_id)
        return CommandResult.success(f"calibration {calibration_id} loaded", calibration_id=calibration_id, change_mm=0.5)

    def rollback_calibration(self) -> CommandResult:
        self._call("rollback_calibration")
        if len(self.calibrations) < 1:
            return CommandResult.failure(ErrorCode.NO_PREVIOUS_CALIBRATION, "there is no previous calibration")
        rolled_back_from = self.calibrations.pop()
        now = self.calibrations[-1] if self.calibrations else geometry_id(self.geometry)
        return CommandResult.success(f"rolled back from calibration {rolled_back_from} to {now}", calibration_id=now,
                                     rolled_back_from=rolled_back_from, change_mm=0.5)

    def validate_calibration(self, geometry: Geometry, calibration_id: str, source: str = "") -> CommandResult:
        self._call("validate_calibration", geometry, calibration_id, source)
        return CommandResult.success(f"calibration {calibration_id} would change the set-points by at most 0.500 mm",
                                     calibration_id=calibration_id, change_mm=0.5)

    def active_geometry(self) -> ActiveGeometry:
        return ActiveGeometry.of(self.geometry, geometry_id(self.geometry), "fake")

    def sequence_records(self) -> SequenceReport | None:
        return SequenceReport(self.sequence.name, "playing", RECORDS) if self.sequence else None

    def events(self, after: int = 0, now_ns: int | None = None) -> EventLog:
        return events_after(self.kept_events, time.monotonic_ns() if now_ns is None else now_ns, after)

    def telemetry(self) -> Telemetry:
        percentiles = Percentiles(10.0, 20.0, 30.0, 40.0)
        return Telemetry(
            t=time.monotonic(),
            state=self.state,
            motion="holding",
            pose_command=(0.0,) * 6,
            pose_measured=None,
            leg_setpoints=(425.0,) * 6,
            leg_feedback=(425.0,) * 6,
            locked_leg=self.locked_leg,
            calibration_id=self.calibrations[-1] if self.calibrations else geometry_id(self.geometry),
            sequence=SequenceTelemetry(self.sequence.name, 1, len(self.sequence.waypoints), "moving") if self.sequence else None,
            faults=(Fault("estop", "operator"),) if self.state == "estop" else (),
            loop=LoopStats(500.0, 1, 0, 0, percentiles, percentiles, 0, 0.0),
            outside_soft_limits=self.outside_soft_limits,
        )


@dataclass
class FakeRecorder:
    """The data recorder's writer as the API calls it: each call noted on ``controller``."""

    controller: FakeController

    def start(self, name, signals, frame, divisor, duration_s, start) -> dict:
        self.controller._call("record", name, tuple(signals), frame, divisor, duration_s, start)
        return {"message": "recording", "path": f"{name}.csv.partial", "side_file": f"{name}.json",
                "rows": round(duration_s * 500 / divisor), "rate_hz": 500.0 / divisor, "duration": duration_s}

    def stop(self) -> dict:
        self.controller._call("record_stop")
        return {"message": "stopped", "name": "r", "csv": "r.csv", "signals": ["lateness"], "frame": "zero",
                "frames": None, "divisor": 1, "loop_rate_hz": 500.0, "rate_hz": 500.0, "duration_s": 1.0,
                "start": "now", "calibration_id": "c", "started_utc": None, "started_monotonic_s": None,
                "first_cycle": 1, "rows_requested": 500, "rows_written": 10, "cycles_missing": 0, "rows_lost": 0,
                "faults_during": False, "ended": "stopped", "columns": [{"name": "t_s", "unit": "s"}]}

    def state(self) -> dict:
        self.controller._call("record_status")
        return {"state": "idle"}

    def reserved(self) -> dict:
        return {}


def start_service(geometry: Geometry, data_dir: Path, telemetry_rate_hz: float = 200.0,
                  instrument: Instrument | None = None, frames_file: Path | None = None) -> SimpleNamespace:
    """A fake controller served on random local ports; ``close()`` when done. The
    instrument (``measure``) defaults to one that sees the feature points at the home
    translation, without noise; ``frames_file``: where the frames are saved (None: not)."""
    context = zmq.Context()
    controller = FakeController(geometry)
    if instrument is None:
        instrument = lambda: [[p + h for p, h in zip(point, geometry.home[:3])] for point in geometry.measurement.feature_points]  # noqa: E731
    server = ApiServer(context, LOCAL, CommandHandler(controller, DataDirectories([data_dir]), instrument, frames_file,
                                                      FakeRecorder(controller), FakeStreamInput()))
    publisher = TelemetryPublisher(context, LOCAL, lambda: jsonable(controller.telemetry()), telemetry_rate_hz)
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


def below_the_loop(service: Service, names: Collection[str]) -> None:
    """This process's threads called one of ``names`` just below the real-time loop of
    ``service`` (nothing without the privilege), as ``hexactl serve`` runs its own."""
    realtime = service.controller.thread.loop.realtime
    if realtime is not None and realtime.fifo_priority is not None:
        fifo_below_loop(realtime.fifo_priority, names)


@contextmanager
def service_here(config: ServiceConfig) -> Iterator[Service]:
    """``Service.start(config)`` in this (pytest's) process, closed on the way out, with
    this thread just below its loop meanwhile, its scheduling restored after. The thread
    polls the service and shares the loop's GIL: at normal priority, preempted by other
    work while holding it, it held the loop up past the actuators' watchdog on a loaded
    host (beside six CPU-bound processes: COMM_TIMEOUT twice a minute, loop lateness up
    to 54 ms; below the loop, none and 10 ms)."""
    policy, parameters = os.sched_getscheduler(0), os.sched_getparam(0)
    service = Service.start(config)
    try:
        below_the_loop(service, {threading.current_thread().name})
        yield service
    finally:
        os.sched_setscheduler(0, policy, parameters)
        service.close()
