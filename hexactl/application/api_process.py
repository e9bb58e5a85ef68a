"""The service's API process: the ZeroMQ command server, the telemetry publisher, and
the controller facade that parses, validates and plans every request, away from the
control loop's GIL (why: :mod:`hexactl.application.loop_link`).

The service (:mod:`hexactl.application.service`) spawns it with :class:`ApiProcess` once its
loop runs, handing it the two pipe ends of the loop link. Its life: connect to the loop
(first report), bind and start the sockets, say where they are bound, then wait. The
service ends it in two steps, so that telemetry keeps flowing while the platform is
brought to rest: ``close_api`` (no more commands), then ``stop``.

If the service's process dies, this one sees its control pipe close and ends; if this
one dies, the service sees its exit (:attr:`ApiProcess.alive`) and shuts down.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path

import zmq

from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.security import CurveServer, CurveServerKeys, SecurityError
from hexactl.adapters.api.stream_receiver import StreamReceiver
from hexactl.adapters.api.server import DEFAULT_HANDLER_TIMEOUT_S, ApiServer
from hexactl.adapters.api.telemetry import TelemetryPublisher
from hexactl.adapters.files.kept_calibration import CalibrationKeeper, KeptCalibration
from hexactl.application.loop_link import RemoteLoop
from hexactl.application.recording import Recordings
from hexactl.application.safety_log import SafetyLog
from hexactl.application.simulator import InstrumentLine, InstrumentSpec, SimulatedMeasurement
from hexactl.application.spawned import STOP, Spawned, SpawnError
from hexactl.control.config import ControllerConfig
from hexactl.control.controller import Controller
from hexactl.control.frames import OperatorFrames
from hexactl.control.snapshot import ControlState, MotionState
from hexactl.kinematics.geometry import Geometry

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"

API_WORKER_NICENESS = 5
"""The API's worker thread, which plans and validates, lowers its scheduling priority by
this much (``nice``; needs no privilege): when the CPUs are contended, the loop's process
gets about three times its share (CFS weights 1024 against 335). Only the worker: the
threads on the way of a stop are raised instead (:data:`URGENT_THREAD_NAMES`)."""

URGENT_THREAD_NAMES = frozenset({"hexactl-api", "hexactl-loop-link"})
"""The API process's threads on the way of a stop: the socket thread that takes ``estop``
and the link's receiver that brings the loop's verdict. With
:attr:`ApiSettings.urgent_niceness` (negative: needs CAP_SYS_NICE) they get a larger
share of a contended CPU, so that CPU-bound work elsewhere delays a stop less. Not
SCHED_FIFO: these threads run Python under a flood (every request is decoded here), and
a real-time thread that does would starve every normal thread of its CPU, among them
the threads holding a loop's GIL in other processes (measured: actuator watchdogs
tripped across the test suite under load)."""

API_SWITCH_INTERVAL_S = 0.001
"""The API process's GIL switch interval (Python's default: 5 ms): the socket thread that
answers ``estop`` gets the GIL within about this long while the worker plans a move."""

STUCK_EXIT_STATUS = 1
"""The API process's exit status when its worker is stuck in a request."""

API_TICKET_START = 1 << 40
"""The API facade's first ticket: the service's own facade (shutdown, tests) counts from 1
on the same loop, and verdicts are found by ticket."""

_CLOSE_API = "close_api"
RECORDING_REST_WAIT_S = 1.0
"""At the service's stop, how long a recording under way waits for the reports of the
platform at rest before it is finished: they arrive a few cycles after the service saw it."""

log = logging.getLogger("hexactl.api")


class ApiStartError(RuntimeError):
    """The API process could not start; the message says why."""


@dataclass(frozen=True, slots=True)
class ApiSettings:
    """What the API process serves (picklable: it crosses to the child).
    ``instrument``: the simulator's, for ``measure`` (None: real hardware, no instrument).
    ``handler_timeout_s``: the watchdog's bound on one request's handling; beyond it the
    API process ends (exit status 1), which the service treats as a dead API."""

    api_endpoint: str
    telemetry_endpoint: str
    telemetry_rate_hz: float
    curve: CurveServerKeys | None
    data_dirs: tuple[Path, ...]
    controller: ControllerConfig
    nominal: Geometry  # the design geometry: the hardware's limits, the calibrations' plausibility
    instrument: InstrumentSpec | None
    log_level: str
    handler_timeout_s: float = DEFAULT_HANDLER_TIMEOUT_S
    urgent_niceness: int = 0  # for URGENT_THREAD_NAMES; 0: the process's
    frames: OperatorFrames = OperatorFrames()  # the operator's, as restored from frames_file
    frames_file: Path | None = None  # where a change of the frames is saved (None: not saved)
    kept_calibration: KeptCalibration | None = None  # where the calibration in force is kept (None: not kept)
    stream_endpoint: str = "tcp://127.0.0.1:*"  # the pose stream's ZeroMQ PULL socket
    stream_udp: tuple[str, int] | None = None  # and its UDP port (None: none)


class ApiProcess:
    """The API in a spawned child process, on the loop link's ``commands`` (write end)
    and ``reports`` (read end), with the simulated instrument's ``instrument_line`` (its
    :class:`~hexactl.application.simulator.InstrumentPort`'s other end; None with real
    hardware); :attr:`api_endpoint`/:attr:`telemetry_endpoint` are where it bound.

    :raises ApiStartError: if it does not start within ``start_timeout_s`` or says it cannot serve
    """

    def __init__(self, settings: ApiSettings, commands: Connection, reports: Connection,
                 start_timeout_s: float = 60.0, instrument_line: Connection | None = None) -> None:
        handed_over = (commands, reports) + ((instrument_line,) if instrument_line is not None else ())
        try:
            self._child = Spawned(_api_main, (settings, commands, reports, instrument_line), name="hexactl-api",
                                  daemon=True, start_timeout_s=start_timeout_s, handed_over=handed_over)
        except SpawnError as error:
            raise ApiStartError(str(error)) from None
        self.api_endpoint, self.telemetry_endpoint = self._child.served

    @property
    def alive(self) -> bool:
        return self._child.alive

    @property
    def exitcode(self) -> int | None:
        return self._child.exitcode

    def close_api(self, timeout_s: float = 5.0) -> None:
        """Stop taking commands (telemetry goes on); returns when the server is closed."""
        self._child.request(_CLOSE_API, timeout_s)

    def close(self, timeout_s: float = 10.0) -> None:
        """End the process (telemetry too); waits for it, terminates it if it will not."""
        self._child.close(timeout_s)


def _await_rest(controller: Controller, timeout_s: float) -> None:
    """Return once the reports show the platform at rest (or no longer enabled), or after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        telemetry = controller.telemetry()
        if telemetry.state != ControlState.ENABLED.value or telemetry.motion == MotionState.HOLDING.value:
            return
        time.sleep(0.01)


def _api_main(settings: ApiSettings, commands: Connection, reports: Connection, instrument_line: Connection | None,
              control: Connection) -> None:
    """The child's life (see the module's docstring)."""
    # Ctrl-C at a terminal, its hangup and a service manager's SIGTERM reach the whole process
    # group: the service handles them and stops this process in order (telemetry until at rest).
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(number, signal.SIG_IGN)
    logging.basicConfig(level=settings.log_level, format=LOG_FORMAT)
    sys.setswitchinterval(API_SWITCH_INTERVAL_S)
    with ExitStack() as closers:
        try:
            remote = RemoteLoop(commands, reports, observe=SafetyLog().observe)
            closers.callback(remote.close)
            controller = Controller(remote, config=settings.controller, nominal=settings.nominal,
                                    ticket_start=API_TICKET_START, frames=settings.frames)
            data = DataDirectories(settings.data_dirs)
            recordings = Recordings(controller, data)
            recordings.start_thread()
            closers.callback(recordings.close)  # also when the service's process is gone: finish what was recorded
            context = zmq.Context()
            closers.callback(context.term)
            curve = None
            if settings.curve:
                try:
                    curve = CurveServer(context, settings.curve)
                except (SecurityError, OSError, ValueError) as error:
                    raise ApiStartError(f"CURVE keys: {error}") from None
                closers.callback(curve.close)
            instrument = None
            if settings.instrument is not None and instrument_line is not None:
                line = InstrumentLine(instrument_line)
                closers.callback(line.close)
                measurement = SimulatedMeasurement(settings.instrument, line)
                instrument = lambda: measurement.measure(_measured_pose(controller))  # noqa: E731
            try:
                stream_input = StreamReceiver(context, settings.stream_endpoint, settings.stream_udp,
                                              controller.stream_target, settings.controller.loop.period_s,
                                              lambda: controller.snapshot.stream, curve)
            except (zmq.ZMQError, OSError) as error:
                raise ApiStartError(f"cannot take a pose stream: {error}") from None
            closers.callback(stream_input.close)
            keeper = None
            if settings.kept_calibration is not None:  # follows the loop's calibration in force from now on
                keeper = CalibrationKeeper(settings.kept_calibration, controller.active_geometry)
                keeper.keep_now()  # the one it starts on (--calibration's, restored, nominal): before serving
            handler = CommandHandler(controller, data, instrument, settings.frames_file, recordings, stream_input,
                                     keeper=keeper)
            try:
                publisher = TelemetryPublisher(context, settings.telemetry_endpoint, handler.record,
                                               settings.telemetry_rate_hz, curve)
                closers.callback(publisher.close)
                server = ApiServer(context, settings.api_endpoint, handler, curve,
                                   handler_timeout_s=settings.handler_timeout_s, on_stuck=_end_stuck,
                                   worker_niceness=API_WORKER_NICENESS, on_wake=remote.heartbeat)  # fmt: skip
            except (zmq.ZMQError, ValueError) as error:  # an endpoint in use or malformed, a bad telemetry rate
                raise ApiStartError(f"cannot serve: {error}") from None
        except (ApiStartError, ConnectionError) as error:
            control.send(str(error))
            return
        publisher.start()
        stream_input.start()
        log.info("pose stream input: %s", ", ".join(f"{kind} {where}" for kind, where in stream_input.endpoints.items()
                                                      if where is not None))
        server.start()
        if settings.urgent_niceness:
            _raise_urgent_threads(settings.urgent_niceness)
        server_open = True
        try:
            control.send((server.endpoint, publisher.endpoint))
            while (message := control.recv()) != STOP:
                if message == _CLOSE_API and server_open:
                    server.close()
                    server_open = False
                control.send(message)
            # After the shutdown's brake: a recording under way ends with the platform at rest,
            # the part an incident's record needs most (it was cut before the brake). Its rows
            # come with the loop's reports, a little behind the service's view of the rest.
            _await_rest(controller, RECORDING_REST_WAIT_S)
            recordings.close()
        except (EOFError, OSError):
            log.warning("the service's process is gone: the API stops")
        finally:
            if server_open:
                server.close()
    # Everything is closed. End now rather than through the interpreter's finalisation,
    # which tears numpy, scipy, pydantic and ZeroMQ down module by module while the
    # service waits for this process: about 0.1 s on the host, seconds in a slow guest
    # (BENCHMARKS.md), enough to use up the shutdown's time.
    logging.shutdown()  # flush the log: os._exit skips it
    os._exit(0)


def _raise_urgent_threads(niceness: int) -> None:
    """``nice`` ``niceness`` for each of :data:`URGENT_THREAD_NAMES` (Linux: per thread id)."""
    for thread in threading.enumerate():
        if thread.name in URGENT_THREAD_NAMES and thread.native_id is not None:
            try:
                os.setpriority(os.PRIO_PROCESS, thread.native_id, niceness)
                log.info("%s thread: nice %d", thread.name, niceness)
            except OSError as error:  # no CAP_SYS_NICE: the normal priority stays
                log.info("%s thread: nice %d not set (%s)", thread.name, niceness, error)


def _end_stuck(description: str) -> None:
    """End this process at once: the worker is stuck in a call that may never return (a
    blocking open, a hung read), so an orderly exit, which closes the ZeroMQ context and
    joins threads, could hang with it. The service sees the exit and brings the platform
    to rest, disables it and exits 1 (:func:`hexactl.application.service.run_service`)."""
    log.error("%s: the API process exits (status %d)", description, STUCK_EXIT_STATUS)
    logging.shutdown()  # flush the log: os._exit skips it
    os._exit(STUCK_EXIT_STATUS)


def _measured_pose(controller: Controller) -> tuple[float, ...] | None:
    """The controller's pose from the feedback, absolute mm/rad (None if it has none):
    within millimetres of the true one, where the simulated instrument solves from."""
    snapshot = controller.snapshot
    if snapshot.pose_measured is None:
        return None
    return tuple(snapshot.active.absolute_from_relative_mm_rad(snapshot.pose_measured))
