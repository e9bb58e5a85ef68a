"""The composition root of ``hexactl serve`` (ros2_control's "manager"): geometry file →
CAN link (or the built-in simulator on a ``memory:`` bus) → control loop → loop link →
API process (command server, telemetry, planning).

Two processes. This one holds the real-time part: the control loop's thread (real-time
where allowed), the CAN link and, with the simulator, the six simulated actuators'
thread. The API process
(:mod:`hexactl.application.api_process`) holds everything that parses, validates, plans or
serialises, so none of it competes with the loop for the GIL
(:mod:`hexactl.application.loop_link` says why and what crosses). The caller's thread only
starts and stops them.

Shutdown (SIGINT/SIGTERM/SIGHUP, or :meth:`Service.close`): the API stops taking commands, a
moving platform brakes to rest, the actuators are disabled (an E-stop if they will not
be), then telemetry, the loop, the link and the simulator stop. If the API process dies,
:func:`run_service` does the same and exits with status 1. Every step is bounded (an API
process that does not answer is killed), so the whole takes at most
:data:`SHUTDOWN_LIMIT_S`; should anything still hang, :func:`run_service` exits anyway.

Real-time by default: the loop thread asks for SCHED_FIFO
(:data:`~hexactl.control.realtime.DEFAULT_FIFO_PRIORITY`) and the process for mlockall;
without the privilege it runs normally and says why
(:func:`~hexactl.control.realtime.allowed`).
"""

from __future__ import annotations

import ipaddress
import logging
import multiprocessing
import os
import select
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Collection
from importlib import resources
from itertools import combinations
from contextlib import ExitStack, suppress
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from types import FrameType
from typing import NoReturn

import can
import zmq

from firmware_proto.codec import LoopRate
from hexactl.adapters.api.security import (
    CurveServerKeys,
    SecurityError,
    check_endpoints,
    client_keys,
    load_server_keys,
)
from hexactl.adapters.api.protocol import (
    DEFAULT_API_ENDPOINT,
    DEFAULT_TELEMETRY_ENDPOINT,
    DEFAULT_TELEMETRY_RATE_HZ,
    check_telemetry_rate,
    endpoints_clash,
    is_local_endpoint,
)
from hexactl.adapters.api.socket_thread import check_bindable
from hexactl.application.api_process import LOG_FORMAT, ApiProcess, ApiSettings, ApiStartError
from hexactl.adapters.can.link import CanActuatorLink, LinkConfig
from hexactl.adapters.can.transport import BusSpecError
from hexactl.adapters.files.atomic import same_file, write_atomic
from hexactl.adapters.files.frames_file import FramesFileError, load_frames
from hexactl.adapters.files.geometry_file import geometry_id, load_geometry
from hexactl.adapters.files.kept_calibration import DEFAULT_FILE as DEFAULT_KEPT_CALIBRATION_FILE
from hexactl.adapters.files.kept_calibration import KeptCalibration, KeptCalibrationError, restore_calibration
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.service_lock import HeldByAnother, hold
from hexactl.application.dashboard import DashboardProcess
from hexactl.application.loop_link import LoopExchange
from hexactl.application.simulator import InstrumentPort, Simulator
from hexactl.application.spawned import Spawned, SpawnError
from hexactl.control.config import ControllerConfig, LoopConfig, SupervisionConfig
from hexactl.control.local_controller import LocalController
from hexactl.control.core import ControlState, MotionState
from hexactl.control.frames import OperatorFrames
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY, RealtimeConfig, describe, fifo_for_threads
from hexactl.control.trajectory import MotionLimits
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS
from hexactl.kinematics.geometry import Geometry, GeometryError

DEFAULT_FRAMES_FILE = "frames.toml"
"""Where the operator's frames are kept, in the service's working directory, unless set."""

SHUTDOWN_STEPS_S = 5.0
"""The time :meth:`Service.close`'s waiting steps share: stop taking commands, brake, let
the API process end. Each waits at most its own bound below and never past this; killing
an API process that has not ended and the rest of the teardown take about a second more."""

CLOSE_API_TIMEOUT_S = 1.0
"""How long shutdown waits for the API process to stop taking commands (milliseconds when
it answers; one that does not is stuck, and is killed when the shutdown's time is up)."""

SHUTDOWN_BRAKE_TIMEOUT_S = 3.0
"""How long shutdown waits for a moving platform to brake to rest before it E-stops
(braking from the legs' top speed at the default limits takes about 1 s)."""

MIN_STEP_S = 0.5
"""The least time a shutdown step gets, even once :data:`SHUTDOWN_STEPS_S` is spent."""

SHUTDOWN_LIMIT_S = 7.0
"""The most :func:`run_service`'s shutdown may take before it exits regardless (status 1):
the bounded steps take at most about 6 s; this catches what nothing foresaw. The
interpreter's own exit takes up to 3 s more on a loaded 2-core host (measured), which
keeps the whole within the 10 s a service manager is promised."""

SIMULATOR_WATCHDOG_CYCLES = 25
SIMULATOR_SUPERVISION = SupervisionConfig(heartbeat_timeout_s=0.2, setpoint_lag_s=0.2, following_error_s=0.3)
"""Timeouts for the built-in simulator: a 25-cycle actuator watchdog (50 ms at 500 Hz)
and 0.2 s heartbeat and set-point supervision instead of the protocol's 5 cycles and
50 ms, and 0.3 s over the following-error limit instead of 0.1 s (a simulated drive
held up catches up with its set-point only after it runs again). A real actuator's firmware runs on its own microcontroller; the simulated ones
share this host's two cores with the loop, the API and whatever else runs, and a
scheduler stall of either thread beyond 11 ms (seen under load) would trip a watchdog
that measures host load, not the controller. Real actuators keep the defaults; missed
cycles show in the loop statistics either way."""

SERVICE_THREAD_NAMES = frozenset({"actuator-bus"})
"""The threads that share the loop's process (and GIL): with ``fifo_priority`` they run
just below it (the main thread too where the service owns its process:
:func:`main_thread_below_loop`)."""

API_START_TIMEOUT_S = 240.0
"""How long the service waits for its API process to start: seconds on an idle host, over
a minute beside four CPU-bound processes on two cores (measured)."""

API_URGENT_NICENESS = -10
"""With a real-time loop (the privilege to raise priorities), the API process's threads
on the way of a stop (:data:`~hexactl.application.api_process.URGENT_THREAD_NAMES`) run at
this ``nice``: about nine times a normal thread's share of a contended CPU (CFS weights
9548 against 1024), without starving anything."""

API_WATCH_INTERVAL_S = 0.5
"""How often :func:`run_service` checks that the API process lives."""

log = logging.getLogger("hexactl.service")


class ServiceError(Exception):
    """The service cannot start as configured; the message says why."""


class _Budget:
    """The time the shutdown's steps share: none until :meth:`start` (a start that fails
    unwinds with each step's own bound)."""

    def __init__(self) -> None:
        self._end = float("inf")

    def start(self, seconds: float) -> None:
        self._end = time.monotonic() + seconds

    def left(self, most: float) -> float:
        """Seconds a step may wait: at most ``most``, at least :data:`MIN_STEP_S`."""
        return max(MIN_STEP_S, min(most, self._end - time.monotonic()))


@dataclass(frozen=True, slots=True)
class ServiceConfig:
    """What ``hexactl serve`` runs.

    ``config_path``: the nominal geometry (None: :func:`default_config_path`);
    ``calibration_path``: a calibration to start with instead; ``can``: the bus of real
    actuators, e.g. ``socketcan:can0`` (None: the simulator, whose true platform has the
    seeded manufacturing errors of :func:`hexactl.sim.true_platform.true_geometry`);
    ``data_dirs``: where requests may read and write files, each of which must exist
    (None: ./recordings, ./calibrations, ./sequences, created if missing, and the
    geometry file's directory; see :func:`data_directories`).
    ``simulator_seed`` seeds the simulator's manufacturing errors and its instrument's
    noise, ``point_sigma_mm`` that noise (1σ per coordinate, mm; None: the geometry's
    ``[measurement] point_sigma_mm``). ``motion``: the controller's pose-space velocity,
    acceleration and jerk limits (the legs' speed limit is the geometry's whatever these are).
    ``fifo_priority``: SCHED_FIFO for the loop thread, and one below for the simulator's
    thread, which shares the GIL with it (None: normal scheduling; the API process's
    threads on the way of a stop then keep the normal priority too, else they get
    :data:`API_URGENT_NICENESS`); ``lock_memory``: mlockall of the
    loop's process. Both on by default; each falls back, logged and in ``status``,
    without the privilege. ``frames_path``: where the operator's frames and soft limits
    are kept across restarts (None: ./frames.toml); read at start (a file that is not
    valid refuses the start), written whenever they change. ``kept_calibration_path``: where
    the calibration in force is kept across restarts (None: ./active_calibration.toml;
    :mod:`~hexactl.adapters.files.kept_calibration`): restored at start without
    ``calibration_path`` (a file that cannot be used refuses the start), written by the
    API process whenever the calibration the loop has in force changes, however it came
    about (even a load answered ``loop_timeout``). ``dashboard_http``: serve the
    browser dashboard there too (``HOST:PORT`` on loopback; None: no dashboard), in a
    process of its own, stopped first at shutdown. ``stream_endpoint``: the pose stream's
    ZeroMQ socket (None: the API's host, a free port); ``stream_udp``: (host, port) where
    its samples are also taken as UDP datagrams (None: no UDP).
    """

    config_path: Path | None = None
    calibration_path: Path | None = None
    can: str | None = None
    rate_hz: int = 500
    api_endpoint: str = DEFAULT_API_ENDPOINT
    telemetry_endpoint: str = DEFAULT_TELEMETRY_ENDPOINT
    telemetry_rate_hz: float = DEFAULT_TELEMETRY_RATE_HZ
    data_dirs: tuple[Path, ...] | None = None
    curve: CurveServerKeys | None = None
    simulator_seed: int = 0
    point_sigma_mm: float | None = None
    motion: MotionLimits = MotionLimits()
    fifo_priority: int | None = DEFAULT_FIFO_PRIORITY
    lock_memory: bool = True
    log_level: str = "INFO"
    frames_path: Path | None = None
    kept_calibration_path: Path | None = None
    dashboard_http: str | None = None
    stream_endpoint: str | None = None
    stream_udp: tuple[str, int] | None = None

    def __post_init__(self) -> None:
        """:raises ValueError: a telemetry rate the publisher cannot keep, named with its range"""
        check_telemetry_rate(self.telemetry_rate_hz)


def _beside(api_endpoint: str) -> str:
    """A free port on the API's host (a TCP endpoint), else on loopback."""
    if api_endpoint.startswith("tcp://"):
        return api_endpoint.rpartition(":")[0] + ":*"
    return "tcp://127.0.0.1:*"


class Service:
    """The running service; :meth:`start` composes and starts it, :meth:`close` stops it.
    ``controller``: a facade on the loop of this process (the API process has its own);
    ``simulator``: the built-in one (None with real actuators)."""

    def __init__(self, controller: LocalController, simulator: Simulator | None, api: ApiProcess, link: LoopExchange,
                 closers: ExitStack, budget: _Budget) -> None:
        self.controller = controller
        self.simulator = simulator
        self.link = link
        """The loop's end of the link to the API process: its counters and state."""
        self.api_endpoint = api.api_endpoint
        self.telemetry_endpoint = api.telemetry_endpoint
        self._api = api
        self._closers = closers
        self._budget = budget

    @property
    def api_alive(self) -> bool:
        """Whether the API process runs (it can only end by a crash or a kill while the
        service runs)."""
        return self._api.alive

    @property
    def api_exitcode(self) -> int | None:
        return self._api.exitcode

    @classmethod
    def start(cls, config: ServiceConfig, serving: Callable[[], object] | None = None) -> Service:
        """Load the geometry, open the actuators, start the loop, then the API process;
        what was started is stopped again if a later step fails. ``serving`` is called
        once the API process serves (clients may enable the actuators from then on):
        :func:`run_service` stops ending the process at once on a signal then.

        :raises ServiceError: for a refused geometry or key file, two options naming one
            file, a kept file that is a link to nothing, kept files another service holds,
            a bus that cannot be opened or an endpoint that cannot be bound
        :raises ~hexactl.adapters.api.security.SecurityError: for a non-loopback endpoint
            without CURVE keys
        """
        # The files first: nothing is read, bound or written before their names are known good.
        config_path = config.config_path or default_config_path()
        frames_path = config.frames_path or Path.cwd() / DEFAULT_FRAMES_FILE
        kept_path = config.kept_calibration_path or Path.cwd() / DEFAULT_KEPT_CALIBRATION_FILE
        _refuse_shared_files(config, config_path, frames_path, kept_path)
        kept_files = tuple((_kept_file(path, what, option, without), what) for path, what, option, without in (
            (kept_path, "the calibration in force", "--keep-calibration", "the nominal geometry"),
            (frames_path, "the operator's frames", "--frames", "no frames and no soft limits")))
        (kept_path, _), (frames_path, _) = kept_files

        # The stream's ZeroMQ socket steers the platform as the API does (UDP is warned of below).
        given = (("--api", config.api_endpoint), ("--telemetry", config.telemetry_endpoint),
                 ("--stream", config.stream_endpoint))
        named = [(option, endpoint) for option, endpoint in given if endpoint]
        zmq_endpoints = [endpoint for _, endpoint in named]
        for (option, endpoint), (other_option, other) in combinations(named, 2):
            if endpoints_clash(endpoint, other):
                raise ServiceError(f"{option} {endpoint} and {other_option} {other} take the same address: give each "
                                   "its own port (tcp://HOST:* takes a free one)")
        check_endpoints(zmq_endpoints, config.curve)  # refused before any word of CURVE
        for endpoint in zmq_endpoints:
            if not is_local_endpoint(endpoint):
                log.warning("%s is reachable from the network: CURVE keys given, only their clients get in", endpoint)
        if config.dashboard_http and config.curve:
            raise ServiceError("--dashboard serves a service on loopback without CURVE; with CURVE keys, run "
                               "hexactl dashboard with a client's keys (--curve-server, --curve-client)")
        if config.curve:  # read here, before the actuators open (the API's process uses them)
            try:
                load_server_keys(config.curve)
            except (SecurityError, OSError, ValueError) as error:
                raise ServiceError(f"CURVE keys: {error}") from None
        for option, endpoint in named:
            try:  # here, before the actuators open; the API process binds them for good
                check_bindable(endpoint)
            except zmq.ZMQError as error:  # it names the endpoint
                raise ServiceError(f"{option}: cannot serve: {error}") from None
        nominal = _load(config_path)

        # Unwound in reverse: API, bring to rest, telemetry, loop, link, simulator, the kept files.
        with ExitStack() as closers:
            for path, what in kept_files:
                try:  # before they are read, and before the actuators open
                    closers.callback(hold(path, what).release)
                except HeldByAnother as error:
                    raise ServiceError(str(error)) from None
            frames = _restored_frames(frames_path)
            log.info("nominal geometry %r (%s) from %s", nominal.name, geometry_id(nominal), config_path)
            active, source, refused = _start_calibration(config.calibration_path, kept_path, nominal, config_path)
            calibration_id = geometry_id(active)
            simulator = None
            if config.can is None:
                simulator = Simulator(nominal, config.simulator_seed, config.point_sigma_mm)
                closers.callback(simulator.close)
            spec = simulator.bus_spec if simulator else config.can
            try:
                watchdog = {"watchdog_cycles": SIMULATOR_WATCHDOG_CYCLES} if simulator else {}
                link = CanActuatorLink.open(spec, LinkConfig(loop_rate=LoopRate(config.rate_hz), **watchdog))
            except (BusSpecError, can.CanError, OSError, ValueError) as error:
                raise ServiceError(f"cannot open the actuators' bus {spec}: {error}") from None
            closers.callback(link.close)
            if simulator:
                log.info("actuators: six simulated on %s, true platform %r; watchdog %d cycles and supervision %g s "
                         "(simulator timeouts: it shares the host with the loop)", spec,
                         simulator.instrument_spec.truth.name, SIMULATOR_WATCHDOG_CYCLES,
                         SIMULATOR_SUPERVISION.heartbeat_timeout_s)
            else:
                log.info("actuators: CAN %s", spec)

            realtime_config = RealtimeConfig(fifo_priority=config.fifo_priority, lock_memory=config.lock_memory)
            loop = LoopConfig(rate_hz=config.rate_hz, realtime=realtime_config)
            supervision = {"supervision": SIMULATOR_SUPERVISION} if simulator else {}
            controller_config = ControllerConfig(loop=loop, motion=config.motion, **supervision)
            try:
                controller = LocalController.in_thread(link, active, calibration_id, calibration_source=str(source),
                                                       config=controller_config, nominal=nominal)
            except ValueError as error:  # a calibration whose [limits] are not the nominal's, or implausible
                raise ServiceError(f"{source}: {error}{refused}") from None
            # said once the loop took it: logged when read, a calibration then refused read as active
            log.info("active calibration %r (%s) from %s", active.name, calibration_id, source)
            for warning in active.identification_warnings:
                log.warning("calibration %s, when identified: %s", calibration_id, warning)
            # What is in force is what a restart restores: the API process keeps it from its start on.
            kept = KeptCalibration(kept_path, geometry_id(nominal))

            pipes = multiprocessing.get_context("spawn")
            commands_in, commands_out = pipes.Pipe(duplex=False)
            reports_in, reports_out = pipes.Pipe(duplex=False)
            # Reports as often as telemetry takes them (verdicts at once whatever the rate).
            exchange = LoopExchange(controller.thread, commands_in, reports_out,
                                    interval_s=1 / config.telemetry_rate_hz,
                                    silence_s=controller_config.supervision.command_silence_s).start()
            closers.callback(exchange.close)
            realtime = controller.start(exchange)
            closers.callback(controller.shutdown)
            log.info("control loop at %d Hz; real-time: %s", config.rate_hz, describe(realtime))
            if realtime.fifo_priority is not None:
                fifo_below_loop(realtime.fifo_priority)

            # Last before the API: a start refused at any step before leaves no directory behind.
            data_dirs = data_directories(config.data_dirs, config_path)
            settings = ApiSettings(config.api_endpoint, config.telemetry_endpoint, config.telemetry_rate_hz, config.curve,
                                   data_dirs, controller_config, nominal,
                                   simulator.instrument_spec if simulator else None, config.log_level,
                                   urgent_niceness=0 if realtime.fifo_priority is None
                                   else API_URGENT_NICENESS, frames=frames, frames_file=frames_path,
                                   kept_calibration=kept,
                                   stream_endpoint=config.stream_endpoint or _beside(config.api_endpoint),
                                   stream_udp=config.stream_udp)  # fmt: skip
            if config.stream_udp and not ipaddress.ip_address(config.stream_udp[0]).is_loopback:
                log.warning("pose stream on UDP %s:%d: UDP has no authentication; whoever reaches that port steers the "
                            "platform while a stream is open (within the workspace and the limits)", *config.stream_udp)
            port = None
            if simulator:
                port = InstrumentPort(simulator.runner.actual_positions_mm).start()
                closers.callback(port.close)  # after the API's process: unwound in reverse
            try:
                api = ApiProcess(settings, commands_out, reports_in, API_START_TIMEOUT_S,
                                 port.line_end if port else None)
            except ApiStartError as error:
                raise ServiceError(str(error)) from None
            if serving is not None:
                serving()
            budget = _Budget()
            closers.callback(lambda: api.close(budget.left(SHUTDOWN_STEPS_S)))  # telemetry flows until at rest
            closers.callback(lambda: _bring_to_rest(controller, budget.left(SHUTDOWN_BRAKE_TIMEOUT_S)))
            closers.callback(lambda: api.close_api(budget.left(CLOSE_API_TIMEOUT_S)))
            if config.dashboard_http:  # started again by its own watcher should it end
                board = DashboardProcess(api.api_endpoint, api.telemetry_endpoint, config.dashboard_http)
                closers.callback(board.close)  # the first to go: it stops sending commands
            security = (f"CURVE, client keys {', '.join(client_keys(config.curve.clients_dir))}" if config.curve
                        else "no authentication (loopback)")
            log.info("API on %s, telemetry on %s at %g Hz; %s", api.api_endpoint, api.telemetry_endpoint,
                     config.telemetry_rate_hz, security)
            log.info("data directories: %s", ", ".join(str(directory) for directory in data_dirs))
            _name_interrupted_recordings(data_dirs[0])
            return cls(controller, simulator, api, exchange, closers.pop_all(), budget)

    def close(self) -> None:
        """Stop taking commands, bring the platform to rest disabled, close everything,
        in at most about :data:`SHUTDOWN_STEPS_S` + 1 s."""
        started = time.monotonic()
        self._budget.start(SHUTDOWN_STEPS_S)
        self.link.expect_silence()  # the API is stopped first: its silence is no reason to brake
        self._closers.close()
        log.info("stopped (shutdown took %.2f s)", time.monotonic() - started)


class ServiceProcess:
    """A :class:`Service` of ``config`` in a child process (spawned), with its endpoints;
    :meth:`close` (or leaving the ``with``) shuts it down cleanly: platform to rest,
    actuators disabled. For a client in this process whose own work (numpy, matplotlib)
    must not hold up the control loop through the GIL: ``hexactl demo``, tests.

    The child ignores SIGINT and SIGHUP: Ctrl-C at the terminal interrupts the client, which
    then decides when the service stops, and a hangup that ends the client closes its pipe,
    which stops the service in order. Like ``hexactl serve`` it watches its API process
    (:class:`ServiceWatch`): if that dies, it brings the platform to rest, disables the
    actuators and ends (:attr:`exitcode` 1).

    :raises ServiceError: if the service does not start (within ``start_timeout_s``)
    """

    def __init__(self, config: ServiceConfig, start_timeout_s: float = 60.0) -> None:
        try:
            # Not a daemon: the service spawns its API process, which a daemon may not. It
            # ends with this process all the same: it stops when its end of the pipe closes.
            self._child = Spawned(_serve, (config,), name="hexactl-service", daemon=False,
                                  start_timeout_s=start_timeout_s)  # fmt: skip
        except SpawnError as error:
            raise ServiceError(str(error)) from None
        self.api_endpoint, self.telemetry_endpoint = self._child.served

    @property
    def pid(self) -> int | None:
        """The service's process id (its API process is a child of it)."""
        return self._child.pid

    @property
    def exitcode(self) -> int | None:
        """None while the service runs; 1 if it ended because its API process died or its
        command stream ended or broke (its log says which)."""
        return self._child.exitcode

    def close(self, timeout_s: float = 30.0) -> None:
        self._child.close(timeout_s)

    def __enter__(self) -> ServiceProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _serve(config: ServiceConfig, connection: Connection) -> None:
    """The child's life: start, say where, serve until told to stop (or orphaned, or the API
    process fails: then exit status 1), close."""
    for number in (signal.SIGINT, signal.SIGHUP):  # the parent decides (the class's docstring)
        signal.signal(number, signal.SIG_IGN)
    logging.basicConfig(level=config.log_level, format=LOG_FORMAT)
    try:
        service = Service.start(config)
    except (ServiceError, SecurityError) as error:
        connection.send(str(error))
        return
    main_thread_below_loop(service)
    watch, problem = ServiceWatch(service), None
    try:
        connection.send((service.api_endpoint, service.telemetry_endpoint))
        while not connection.poll(API_WATCH_INTERVAL_S):  # until told to stop, or the parent is gone
            if problem := watch.problem():
                log.error("%s: shutting down", problem)
                break
    except (EOFError, OSError):
        pass  # the parent is gone: stop too
    finally:
        service.close()
    if problem:
        sys.exit(1)


KEPT_IF_IGNORED = (signal.SIGINT, signal.SIGHUP)
"""The shutdown signals a service leaves ignored when its parent ignores them (``nohup``,
``&`` in a script); SIGTERM always ends it."""


def run_service(config: ServiceConfig) -> NoReturn:
    """``hexactl serve``: log to stderr, run until SIGINT, SIGTERM or SIGHUP (its terminal or
    SSH session is gone: no reason to leave a platform moving with no controller), shut
    down cleanly and end the process: status 0, or 1 if the API process died or its
    command stream ended or broke (the platform is then brought to rest as at a stop); the
    link's dropped non-commands are logged.

    A signal during the start, before the API process serves, ends the process at once
    (:func:`_end_start_up`: nothing can have been enabled yet). SIGINT or SIGHUP inherited
    as ignored (``hexactl serve … &`` from a script, ``nohup``) stays ignored, as the parent
    wished; SIGTERM always ends the service.

    :raises ServiceError: if the service does not start (see :meth:`Service.start`)
    """
    logging.basicConfig(level=config.log_level, format=LOG_FORMAT)
    status = 0
    numbers = [number for number in ShutdownSignals.SIGNALS
               if number not in KEPT_IF_IGNORED or signal.getsignal(number) is not signal.SIG_IGN]
    with ShutdownSignals(numbers, on_start_up=_end_start_up) as signals:
        service = Service.start(config, serving=signals.serving)
        signals.serving()
        main_thread_below_loop(service)
        try:
            watch = ServiceWatch(service)
            while (received := signals.wait(API_WATCH_INTERVAL_S)) is None:
                if problem := watch.problem():
                    log.error("%s: shutting down", problem)
                    status = 1
                    break
            else:
                log.info("%s: shutting down", received.name)
        finally:
            backstop = threading.Timer(SHUTDOWN_LIMIT_S, _exit_now)
            backstop.daemon = True
            backstop.start()
            service.close()
            backstop.cancel()
        # Everything is closed. End now (a signal from here on is only noted) rather than
        # through the interpreter's finalisation, which tears numpy, scipy and pydantic down
        # module by module after "stopped" (0.2 s on the host, seconds in a slow guest:
        # BENCHMARKS.md) while a service manager waits.
        logging.shutdown()  # flush the log: os._exit skips it
        sys.stdout.flush()
        os._exit(status)


class ServiceWatch:
    """What the main thread of a service's own process (``hexactl serve``,
    :class:`ServiceProcess`) watches every :data:`API_WATCH_INTERVAL_S`: it says on the
    service's log when the loop link drops a message that is not a command, and when it
    finds the API process silent and heard again (the API's own log, where the loop's
    events are written, is silent with it)."""

    def __init__(self, service: Service) -> None:
        self._service = service
        self._rejected = 0
        self._longest_silence_s = 0.0  # of the present silence as seen; 0: none

    def problem(self) -> str | None:
        """Log what changed since the last call; why the service cannot go on taking
        commands (its API process died, or its command stream ended or broke), or None."""
        link = self._service.link
        if link.rejected > self._rejected:  # a bug of ours if ever: the API process sends only commands
            log.warning("the loop link dropped %d messages that were not commands", link.rejected - self._rejected)
            self._rejected = link.rejected
        self._watch_silence(link)
        return _api_problem(self._service)

    def _watch_silence(self, link: LoopExchange) -> None:
        silent_s = link.silent_s
        if link.silent:
            if not self._longest_silence_s:
                log.warning("nothing from the API process for %.1f s (frozen or starved of CPU): a motion under way "
                            "is braked to rest; an E-stop through the API may not arrive: use the hardware E-stop",
                            silent_s)
            self._longest_silence_s = max(self._longest_silence_s, silent_s)
        elif self._longest_silence_s:
            log.info("the API process is heard again after %.1f s or more of silence", self._longest_silence_s)
            self._longest_silence_s = 0.0


def _end_start_up(received: signal.Signals) -> NoReturn:
    """A signal while the service starts, before its API process serves: no client can
    have enabled the actuators, so nothing moves and nothing needs braking. End at once,
    however long the start would still take (an API process starting on a loaded host: a
    minute and more), with one line and no traceback: the child processes killed (the
    dashboard's ends by itself), status 130 for SIGINT (as the command line's Ctrl-C),
    death by the signal for SIGTERM and SIGHUP (143 and 129 to a shell; what it did before
    the handler was set).

    Runs in the signal handler: no lock, no logging (the interrupted main thread may hold
    the log's)."""
    os.write(sys.stderr.fileno(), f"hexactl serve: {received.name} during start-up: stopped before serving\n".encode())
    for child in multiprocessing.active_children():
        child.kill()
    if received != signal.SIGINT:
        signal.signal(received, signal.SIG_DFL)
        os.kill(os.getpid(), received)
    os._exit(128 + received)


class ShutdownSignals:
    """SIGINT, SIGTERM and SIGHUP for a main thread that watches the service: inside the ``with``,
    :meth:`wait` returns the first one received.

    The handler only appends to a list and the wake-up file descriptor (written by the
    interpreter's C handler) ends the wait. It takes no lock: CPython runs a Python handler
    between two bytecodes of the main thread, perhaps while that thread holds the very
    lock a ``threading.Event.set()`` would take, and then waits for itself for ever (the
    ``signal`` module's warning; python/cpython#126434). A service hung that way after
    "SIGTERM" with no backstop running yet.

    ``numbers``: the signals it takes (default :data:`SIGNALS`). ``on_start_up``: called
    with a signal received before :meth:`serving` instead of noting it (it may end the
    process).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

    def __init__(self, numbers: Collection[signal.Signals] = SIGNALS,
                 on_start_up: Callable[[signal.Signals], object] | None = None) -> None:
        self._numbers = tuple(numbers)
        self._on_start_up = on_start_up
        self._received: list[signal.Signals] = []
        self._wake_read, self._wake_write = socket.socketpair()
        self._previous: dict[signal.Signals, object] = {}
        self._previous_wakeup_fd = -1

    def __enter__(self) -> ShutdownSignals:
        for sock in (self._wake_read, self._wake_write):
            sock.setblocking(False)
        self._previous_wakeup_fd = signal.set_wakeup_fd(self._wake_write.fileno(), warn_on_full_buffer=False)
        self._previous = {number: signal.signal(number, self._handle) for number in self._numbers}
        return self

    def __exit__(self, *exc_info: object) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        signal.set_wakeup_fd(self._previous_wakeup_fd)
        self._wake_read.close()
        self._wake_write.close()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self._on_start_up is not None:
            self._on_start_up(signal.Signals(signum))
        self._received.append(signal.Signals(signum))

    def serving(self) -> None:
        """From now on a signal is noted, for :meth:`wait` (no more ``on_start_up``)."""
        self._on_start_up = None

    def wait(self, timeout_s: float) -> signal.Signals | None:
        """The first signal received, waiting up to ``timeout_s`` s for one (None: none)."""
        if not self._received:
            select.select([self._wake_read], [], [], timeout_s)
            with suppress(BlockingIOError):
                self._wake_read.recv(64)
        return self._received[0] if self._received else None


def _exit_now() -> None:
    """End the process at once, children first: shutdown took longer than
    :data:`SHUTDOWN_LIMIT_S`. Actuators the loop no longer heartbeats stop by their own
    watchdog."""
    log.error("shutdown did not finish within %g s: killing the child processes and exiting (status 1)",
              SHUTDOWN_LIMIT_S)
    for child in multiprocessing.active_children():
        child.kill()
    logging.shutdown()  # flush the log: os._exit skips it
    os._exit(1)


def _api_problem(service: Service) -> str | None:
    """Why the service cannot go on taking commands (None: it can)."""
    if not service.api_alive:
        return f"the API process died (exit status {service.api_exitcode})"
    link = service.link
    if not link.commands_open:
        return f"the API process's command stream {f'is unreadable ({link.corrupt})' if link.corrupt else 'ended'}"
    return None


def fifo_below_loop(loop_priority: int, names: Collection[str] = SERVICE_THREAD_NAMES) -> None:
    """SCHED_FIFO just below the loop's ``loop_priority`` for this process's threads called
    one of ``names``: those that share the loop's GIL (see :func:`~hexactl.control.realtime.set_fifo`)."""
    priority = max(1, loop_priority - 1)
    for name, refused in fifo_for_threads(priority, names).items():
        log.info("%s thread: %s", name, refused or f"SCHED_FIFO {priority}")


def main_thread_below_loop(service: Service) -> None:
    """The calling thread, the main thread of a process the service owns (``hexactl serve``,
    :class:`ServiceProcess`), under SCHED_FIFO just below the service's real-time loop: it
    wakes to watch the service and shares the loop's GIL, and preempted by other processes
    while holding it, it stalls the loop (up to 0.5 s seen in the vcan tests' guest, past
    the actuators' watchdog). Not done by :meth:`Service.start`: a program that embeds a
    service keeps its own thread's scheduling."""
    realtime = service.controller.thread.loop.realtime
    if realtime is not None and realtime.fifo_priority is not None:
        fifo_below_loop(realtime.fifo_priority, {threading.current_thread().name})


def _bring_to_rest(controller: LocalController, timeout_s: float) -> None:
    """Brake to rest and disable; E-stop if that does not happen within ``timeout_s``."""
    telemetry = controller.telemetry()
    if telemetry.state != ControlState.ENABLED.value:  # the actuators hold by themselves
        faults = "; ".join(f"{fault.code}: {fault.message}" for fault in telemetry.faults)
        log.info("%s%s at %s (measured): nothing to brake", telemetry.state, f" ({faults})" if faults else "",
                 _pose_text(telemetry.pose_measured))
        return

    def at_rest() -> bool:  # a sequence dwelling is holding, yet disable would be refused as busy
        now = controller.telemetry()
        return now.motion == MotionState.HOLDING.value and now.sequence is None

    if not at_rest():
        controller.stop()
        deadline = time.monotonic() + timeout_s
        while not at_rest() and time.monotonic() < deadline:
            time.sleep(0.05)
    rest = controller.telemetry()
    log.info("platform %s at %s (commanded, relative to the zero posture; measured %s)",
             "at rest" if at_rest() else "still moving", _pose_text(rest.pose_command), _pose_text(rest.pose_measured))
    result = controller.disable()
    if result.ok:
        log.info("actuators disabled")
    else:
        log.warning("disable refused (%s: %s): E-stop", result.error, result.message)
        controller.estop()


def _pose_text(pose: tuple[float, ...] | None) -> str:
    """``x 1.000 mm, …, yaw 5.000 deg`` (relative to the zero posture), or ``unknown``."""
    if pose is None:
        return "unknown"
    return ", ".join(f"{axis} {value:.3f} {unit}" for axis, unit, value in zip(POSE_AXES, POSE_UNITS, pose))


_KEPT_FOR_A_RESTART = {"--frames": "the operator's frames", "--keep-calibration": "the calibration in force"}
"""The files serve writes (and, the calibration's, removes), by option: what each keeps."""
_READ_AT_START = {"--config": "the nominal geometry", "--calibration": "the calibration to start with"}
"""The files serve only reads, by option: what each holds."""


def _refuse_shared_files(config: ServiceConfig, config_path: Path, frames_path: Path, kept_path: Path) -> None:
    """Refuse a file serve writes that another of its options names too, by any name (a
    relative path, a symbolic or hard link): a geometry restored as the kept calibration
    from the ``--config`` file is the nominal one, and the kept file, "nothing to keep",
    was removed; ``--frames`` and ``--keep-calibration`` would overwrite each other.

    :raises ServiceError: naming both options, the file and what to do
    """
    files = [("--config", config_path, config.config_path is not None)]
    if config.calibration_path is not None:
        files.append(("--calibration", config.calibration_path, True))
    files += [("--frames", frames_path, config.frames_path is not None),
              ("--keep-calibration", kept_path, config.kept_calibration_path is not None)]
    for (option, path, given), (other, other_path, other_given) in combinations(files, 2):
        if (option in _READ_AT_START and other in _READ_AT_START) or not same_file(path, other_path):
            continue
        both = (f"{_option_text(option, path, given)} and {_option_text(other, other_path, other_given)} name the "
                f"same file, {os.path.realpath(path)}")
        if option in _READ_AT_START:
            raise ServiceError(f"{both}: the service rewrites or removes {other}'s file to keep "
                               f"{_KEPT_FOR_A_RESTART[other]} for a restart, and would destroy "
                               f"{_READ_AT_START[option]} in it; give {other} a file of its own, or copy the file and "
                               f"give the copy to {option}")
        raise ServiceError(f"{both}: the service keeps {_KEPT_FOR_A_RESTART[option]} and "
                           f"{_KEPT_FOR_A_RESTART[other]} for a restart, and each would overwrite the other; give each "
                           "option a file of its own")


def _kept_file(path: Path, what: str, option: str, without: str) -> Path:
    """Where ``option`` (``path``) keeps ``what``: the file itself, or, for a symbolic link,
    its target, which is read, held and written (written over, the link would become a
    file of its own, and the file it led to, on a shared disk say, would keep the old).

    :raises ServiceError: for a folder that is not there, or a link to nothing (``without``
        it, the service would start as if nothing were kept)
    """
    if not path.parent.is_dir():  # a mistyped directory: nothing could be kept there, nor read back
        raise ServiceError(f"{option} {path}: no such directory {path.parent} to keep {what} in; create it, "
                           f"or correct {option}")
    if not path.is_symlink():
        return path
    target = Path(os.path.realpath(path))
    if not target.exists():  # not "nothing kept": the file is elsewhere, out of reach
        raise ServiceError(f"{option} {path}: a symbolic link to {target}, which is not there (a disk not "
                           f"mounted?): {what} kept there can be neither restored nor kept; mount or restore the "
                           f"link's target, or remove the link to start with {without}")
    log.info("%s %s: a link to %s, where %s is kept", option, path, target, what)
    return target


def _name_interrupted_recordings(directory: Path) -> None:
    """Log the recordings a service stopped in mid-recording left in ``directory`` (the
    recorder's): their rows are kept, under a name no reader of finished recordings takes."""
    try:
        interrupted = sorted(directory.glob("*.csv.partial"))
    except OSError:
        return
    for path in interrupted:
        log.warning("%s: a recording not finished (a service stopped during it, or another's under way): its rows "
                    "are kept; hexactl plot draws it; once no service writes it, rename it to .csv or remove it", path)


def _option_text(option: str, path: Path, given: bool) -> str:
    return f"{option} {path}" if given else f"{option} (default {path})"


def _restored_frames(path: Path) -> OperatorFrames:
    """The operator's frames kept in ``path`` (none set: the defaults).

    :raises ServiceError: naming the file and what is wrong with it: a service must not
        start without the soft limits its operator set
    """
    if not path.exists():
        log.info("no operator frames saved in %s: none set, no soft limits", path)
        return OperatorFrames()
    try:
        frames = load_frames(path)
    except FramesFileError as error:
        raise ServiceError(f"{error}\nfix the file, or remove it to start with no frames and no soft limits") from None
    log.info("operator frames restored from %s", path)
    return frames


def _start_calibration(calibration_path: Path | None, kept_path: Path, nominal: Geometry,
                       config_path: Path) -> tuple[Geometry, str, str]:
    """The geometry to start with, where it came from, and what to add to its refusal:
    ``calibration_path``'s, else the one kept in ``kept_path`` (the calibration in force
    when the service last ran), else ``nominal``.

    :raises ServiceError: for a calibration file, or a kept one, that cannot be used
    """
    if calibration_path:
        active = _load(calibration_path)
        log.info("calibration %r (%s) read from %s", active.name, geometry_id(active), calibration_path)
        return active, str(calibration_path), ""
    remedy = (f"\n{kept_path} keeps the calibration in force when the service last ran: give --calibration FILE, "
              "or remove the file to start on the nominal geometry")
    if not kept_path.exists():
        log.info("no calibration kept in %s: starting on the nominal geometry", kept_path)
        return nominal, str(config_path), ""
    try:
        active, source = restore_calibration(kept_path)
    except (GeometryError, KeptCalibrationError) as error:
        raise ServiceError(f"{error}{remedy}") from None
    log.info("calibration %r (%s) read from %s, where it was kept (loaded from %s)", active.name,
             geometry_id(active), kept_path, source)
    return active, source, remedy


def _load(path: Path) -> Geometry:
    try:
        return load_geometry(path)
    except GeometryError as error:
        raise ServiceError(str(error)) from None


EXAMPLE_SEQUENCES = resources.files("hexactl.application") / "example_sequences"
"""The example sequence files (``*.toml``) that :func:`data_directories` puts into the
``./sequences`` it creates."""


def data_directories(configured: tuple[Path, ...] | None, config_path: Path) -> tuple[Path, ...]:
    """The service's data directories: ``configured``, each of which must exist (one
    created for a mistyped ``--data-dir`` would take recordings where nobody looks for
    them), else ./recordings, ./calibrations and ./sequences, each created (and logged)
    if missing, ./sequences with the example sequences, and the directory of
    ``config_path``.

    :raises ServiceError: naming a configured directory that does not exist, or a
        default one that cannot be created
    """
    if configured:
        missing = [str(directory) for directory in configured if not directory.is_dir()]
        if missing:
            raise ServiceError(f"data directory {', '.join(missing)}: no such directory; create it, or correct "
                               "--data-dir")
        return configured
    working = Path.cwd()
    recordings, calibrations, sequences = (working / name for name in ("recordings", "calibrations", "sequences"))
    for directory in (recordings, calibrations):
        _create_data_directory(directory)
    if _create_data_directory(sequences):
        examples = sorted((entry for entry in EXAMPLE_SEQUENCES.iterdir() if entry.name.endswith(".toml")),
                          key=lambda entry: entry.name)
        try:
            for example in examples:
                write_atomic(sequences / example.name, example.read_bytes(), overwrite=False)  # never over a file
        except OSError as error:  # a convenience: the service runs without them
            log.warning("example sequences not written into %s: %s", sequences, error)
        else:
            log.info("example sequences in %s: %s", sequences, ", ".join(example.name for example in examples))
    return recordings, calibrations, sequences, config_path.resolve().parent


def _create_data_directory(directory: Path) -> bool:
    """Create ``directory`` unless it exists; whether it did. :class:`ServiceError` if it
    cannot, or something else has its name."""
    try:
        directory.mkdir()
    except FileExistsError:
        if not directory.is_dir():
            raise ServiceError(f"data directory {directory}: exists but is not a directory; move it away, or give "
                               "--data-dir") from None
        return False
    except OSError as error:
        raise ServiceError(f"data directory {directory}: cannot create it: {error.strerror}; run serve where it "
                           "may, or give --data-dir") from None
    log.info("created data directory %s", directory)
    return True
