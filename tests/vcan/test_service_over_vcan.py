"""The whole service against the simulated actuators in another process over real SocketCAN:
``hexactl sim-actuators --can socketcan:vcan0`` and the service (``run_service``, what
``hexactl serve --can socketcan:vcan0`` runs) as two processes, as in production, driven
through the API client.

Collected only where vcan0 exists (tests/conftest.py); elsewhere tests/test_vcan_in_uml.py runs
them inside user-mode Linux: one CPU shared by the loop, the simulator and pytest, in a host
process that a loaded host preempts. There:

- the loop stalls for tens of milliseconds (up to 87 ms seen), past the protocol's timeouts
  that the service keeps for real actuators: a 5-cycle actuator watchdog (11 ms at 500 Hz,
  22 ms at 250 Hz) and 50 ms supervision. So, as tests/vcan/test_link_sim_process.py does
  for the link, the service runs at 250 Hz with the longest watchdog the protocol allows
  (100 cycles, 0.4 s) and 2 s supervision. ``hexactl serve`` cannot be told either (its
  ``--rate`` takes 500 or 1000, the protocol's LoopRate also 250; ServiceConfig has no
  timeouts), so the service process runs ``run_service`` — what ``hexactl serve`` runs —
  with those settings (and longer waits for the loop's verdict on a command and for a
  shutdown) replaced (:data:`SERVE`);
- the simulator, which stands for actuators with microcontrollers of their own, falls behind
  the bus when the guest is starved, and its firmwares' watchdogs tripped even at 0.4 s
  while the loop was never more than 25 ms late. So it runs under SCHED_FIFO
  :data:`SIMULATOR_FIFO` once it is ready, and the service's loop thread under
  :data:`SERVICE_FIFO` (both above pytest), where that is permitted (root, as in the guest);
  elsewhere both keep normal scheduling. At the same priority neither preempts the other,
  as two microcontrollers would not: the simulator reads a cycle's frames in one wake-up
  after the loop has sent them all (above the loop it woke for each, even though they go
  out in one system call: 72 % of the guest's CPU against 30 %), and the loop, which reads
  each cycle the answers to the previous cycle's SYNC, cannot starve it (below the loop,
  its watchdogs tripped during every move). What runs under SCHED_FIFO must leave the guest's
  CPU idle time, or everything below it gets only the kernel's 5 % for non-real-time tasks:
  so the simulator ticks at :data:`SIMULATOR_TICK_MS`, and start-ups (imports) run at normal
  priority.

Nothing here asserts timing: the waits are generous bounds that turn a hang into a failure.
The tests share one service and run in file order, each starting from an enabled platform at
rest.
"""

from __future__ import annotations

import functools
import json
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from firmware_proto.codec import Fault
from hexactl.adapters.api.client import CommandError, HexactlClient, TelemetrySubscriber
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.adapters.files.config_path import default_config_path
from hexactl.kinematics.geometry import Geometry
from tests.reliability.support import ATTEMPTS, is_stall, tolerating_stalls
from tools.serving import wait_until

pytestmark = pytest.mark.vcan

SPEC = "socketcan:vcan0"
RATE_HZ = 250
WATCHDOG_CYCLES = 100
SUPERVISION_S = 2.0
"""Heartbeat and set-point supervision: the simulator process went 0.4 s without a frame
when the host was loaded by other work (a starved guest, not a lost link)."""
COMMAND_TIMEOUT_S = 5.0
"""How long the API waits for the loop's verdict on a command (the service's 0.5 s ran out once in the guest)."""
SHUTDOWN_STEPS_S = 20.0
SHUTDOWN_LIMIT_S = 30.0
"""The service's shutdown budget and its backstop (5 and 7 s, hexactl.application.service):
in a guest starved to a tenth of a CPU a SIGTERM'd service took 7 s to log its first step,
and the backstop ended it with status 1, the safe way, but not the one these tests check."""
ENABLE_TRIES = 3
"""Enabling again after a stall of the starved guest latched a fault on the way to rest."""
SERVICE_FIFO = 10
SIMULATOR_FIFO = SERVICE_FIFO
"""The same priority: neither preempts the other (see the module's docstring)."""
SIMULATOR_TICK_MS = 4.0
"""The simulator's physics tick, ms (``hexactl sim-actuators`` defaults to 1): its ticks
alone took 39 % of the guest's CPU on an idle host and all of it on a busy one (the
guest's CPU is a host process's share), so that, under SCHED_FIFO, it left the service and pytest the kernel's 5 % for non-real-time tasks: services that took
minutes to start, verdicts later than any timeout. A tick of the loop's period keeps the
drives' lag and the watchdog's resolution well inside what the tests judge (mm, 0.4 s);
frames are still answered as they arrive, not on the tick."""
WAIT_S = 60.0
"""Bound on anything to happen (the guest is slow), s."""
POSE_ABS = 0.05
"""Measured against commanded pose, mm and deg: FK of sensor readings in 1 µm steps."""
SENSOR_STEP_MM = 0.001
CLI = [sys.executable, "-m", "hexactl.adapters.cli.main"]
SERVE = """
import functools, json, os, sys
from pathlib import Path
from hexactl.application import service
from hexactl.control.config import SupervisionConfig
guest = json.loads(sys.argv[1])
service.LinkConfig = functools.partial(service.LinkConfig, watchdog_cycles=guest["watchdog_cycles"])
supervision = SupervisionConfig(heartbeat_timeout_s=guest["supervision_s"], setpoint_lag_s=guest["supervision_s"])
service.ControllerConfig = functools.partial(service.ControllerConfig, supervision=supervision,
                                             command_timeout_s=guest["command_timeout_s"])
service.SHUTDOWN_STEPS_S, service.SHUTDOWN_LIMIT_S = guest["shutdown_steps_s"], guest["shutdown_limit_s"]
sys.exit(service.run_service(service.ServiceConfig(
    can=guest["can"], rate_hz=guest["rate_hz"], api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
    data_dirs=(Path(guest["data_dir"]),), fifo_priority=guest["fifo"])))
"""
"""``hexactl serve --can SPEC`` (``run_service``) with the guest's rate and timeouts, which
neither ``hexactl serve`` nor ServiceConfig can set, under SCHED_FIFO where permitted (see the
module's docstring). Its argument: those settings as JSON (:func:`guest_settings`)."""


wait_for = functools.partial(wait_until, timeout_s=WAIT_S)


@dataclass
class Served:
    """The service in its own process (:data:`SERVE`); its stderr kept in ``log`` by a
    thread (a full pipe would block the service)."""

    process: subprocess.Popen
    api: str = ""
    telemetry: str = ""
    log: list[str] = field(default_factory=list)
    reader: threading.Thread | None = None

    def text(self) -> str:
        return "".join(self.log)

    def final_text(self) -> str:
        """The whole log once the process has exited: waits for the reader to reach
        end-of-file (the exit can be seen before the last lines are read)."""
        if self.reader is not None:
            self.reader.join(WAIT_S)
        return self.text()


def guest_settings(data_dir: Path) -> dict:
    """What :data:`SERVE` reads: the bus, rate (Hz), data directory, actuator watchdog
    (cycles), supervision, command and shutdown timeouts (s), SCHED_FIFO priority."""
    return {"can": SPEC, "rate_hz": RATE_HZ, "data_dir": str(data_dir), "watchdog_cycles": WATCHDOG_CYCLES,
            "supervision_s": SUPERVISION_S, "command_timeout_s": COMMAND_TIMEOUT_S,
            "shutdown_steps_s": SHUTDOWN_STEPS_S, "shutdown_limit_s": SHUTDOWN_LIMIT_S, "fifo": SERVICE_FIFO}


@pytest.fixture(scope="module")
def nominal() -> Geometry:
    return load_geometry(default_config_path())


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("data")


@contextmanager
def simulated_actuators() -> Iterator[subprocess.Popen]:
    """``hexactl sim-actuators --can SPEC`` in its own process, under SCHED_FIFO
    :data:`SIMULATOR_FIFO` where permitted (``--fifo``: set once it is ready, as its
    start-up, imports taking tens of seconds of the guest's CPU, would starve the rest),
    once it says it is ready; killed on leaving unless it has ended
    (:func:`terminate_simulator` ends it cleanly)."""
    process = subprocess.Popen([*CLI, "sim-actuators", "--can", SPEC, "--seed", "3", "--tick-ms", str(SIMULATOR_TICK_MS),
                                "--fifo", str(SIMULATOR_FIFO)],
                               stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        ready = json.loads(process.stdout.readline() or "{}")
        assert ready.get("ready"), process.stderr.read()
        assert ready["scheduling"].startswith(f"SCHED_FIFO {SIMULATOR_FIFO}"), ready  # set, or why not
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


@contextmanager
def running_service(data_dir: Path) -> Iterator[Served]:
    """:data:`SERVE` in its own process, once it has said where its API and telemetry are;
    killed on leaving unless it has ended (:func:`terminate_service` ends it cleanly)."""
    process = subprocess.Popen([sys.executable, "-c", SERVE, json.dumps(guest_settings(data_dir))],
                               stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    served = Served(process)
    try:
        for line in process.stderr:
            served.log.append(line)
            if match := re.search(r"API on (\S+), telemetry on (\S+) at", line):
                served.api, served.telemetry = match.groups()
                break
        assert served.api, served.text()
        served.reader = threading.Thread(target=lambda: served.log.extend(process.stderr), daemon=True)
        served.reader.start()
        yield served
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


ACTUATOR_ESTOP = "an actuator reports E-stop (hardware chain)"
RESET_RETRY_S = 0.5  # beyond the actuators' E-stop hold-off (firmware_proto: 250 ms)


_STOPPED_BY_WATCHDOGS = re.compile(r"hexactl\.service: fault \(((?:actuator_fault: leg \d reports \w+, faults: "
                                   r"comm_timeout \(0x1\)(?:; )?)+)\)"
                                   r" at .*: nothing to brake")


def terminate_service(served: Served) -> bool:
    """SIGTERM: the service must disable the actuators and exit with status 0. True when
    it found them already stopped by their own watchdogs (every fault latched COMM_TIMEOUT
    alone: a guest starved past the 0.4 s watchdog while shutting down), the other safe
    end: then they hold by themselves and there is nothing to disable."""
    served.process.send_signal(signal.SIGTERM)
    try:
        code = served.process.wait(WAIT_S)
    except subprocess.TimeoutExpired:  # what it logged is what says where it hung
        served.process.kill()
        served.process.wait()
        pytest.fail(f"the service did not exit within {WAIT_S:g} s of SIGTERM; its log:\n{served.final_text()}")
    assert code == 0, served.final_text()
    log = served.final_text()
    assert "SIGTERM: shutting down" in log and "stopped" in log, log
    if "actuators disabled" in log:
        return False
    assert _STOPPED_BY_WATCHDOGS.search(log), log
    print("the actuators' watchdogs had stopped them before the service could disable them (a starved guest)")
    return True


def terminate_simulator(simulator: subprocess.Popen, tolerate_watchdog: bool = False) -> None:
    """SIGTERM: the simulator must exit with status 0, every actuator disabled without a
    fault, and no frame rejected in its whole run (its final report).

    ``tolerate_watchdog``: an actuator may also have ended stopped by its own watchdog
    (FAULT with COMM_TIMEOUT alone: the other safe end, which a guest starved past the
    0.4 s watchdog just before the service's DISABLE produces); never still enabled."""
    simulator.send_signal(signal.SIGTERM)
    out, err = simulator.communicate(timeout=WAIT_S)
    assert simulator.returncode == 0, err
    report = json.loads(out.strip().splitlines()[-1])
    ends = list(zip(report["states"], report["faults"]))
    safe = {("DISABLED", 0), *([("FAULT", int(Fault.COMM_TIMEOUT))] if tolerate_watchdog else [])}
    assert set(ends) <= safe, report
    if ("FAULT", int(Fault.COMM_TIMEOUT)) in ends:
        print(f"actuators stopped by their watchdog before the service's DISABLE (a starved guest): {report}")
    assert report["rejected_frames"] == [0] * 6, report


@pytest.fixture(scope="module")
def simulator() -> Iterator[subprocess.Popen]:
    with simulated_actuators() as process:
        yield process


@pytest.fixture(scope="module")
def service(simulator: subprocess.Popen, data_dir: Path) -> Iterator[Served]:
    with running_service(data_dir) as served:
        yield served


@pytest.fixture(scope="module")
def client(service: Served) -> Iterator[HexactlClient]:
    with HexactlClient(service.api, timeout_s=WAIT_S) as client:
        yield client


def status(client: HexactlClient) -> dict:
    return client.call("status")["status"]


def wait_status(client: HexactlClient, accept: Callable[[dict], bool], what: str, timeout_s: float = WAIT_S) -> dict:
    """Poll the status until ``accept`` takes a record; that record. On time-out the
    status's state, motion, faults and loop counters say why."""

    def why(record: dict) -> str:
        loop = {k: record["loop"][k] for k in ("cycles", "missed", "skipped", "lateness_us")}
        return (f"status {record['state']}, {record['motion']}, faults {record['faults']}, "
                f"sequence {record['sequence']}, loop {loop}")

    return wait_until(lambda: accept(record := status(client)) and record, what, timeout_s,
                      seen=lambda: why(status(client)))


def at_rest(record: dict) -> bool:
    """Enabled, holding, no sequence playing."""
    return record["state"] == "enabled" and record["motion"] == "holding" and record["sequence"] is None


def arrived(record: dict) -> bool:
    """At rest with every actuator at its set-point (the drives lag the commands, and a
    calibration's set-point ramp does not count as motion)."""
    return at_rest(record) and all(abs(f - s) <= SENSOR_STEP_MM for f, s in zip(record["leg_feedback"], record["leg_setpoints"]))


def wait_arrived(client: HexactlClient, accept: Callable[[dict], bool], what: str, timeout_s: float = WAIT_S) -> dict:
    """:func:`wait_status` for a motion's end (``accept``); a fault latched on the way fails
    at once, naming it, rather than after the wait (so that :func:`tolerating_stalls` can
    start again from rest when it is a starved guest's)."""
    record = wait_status(client, lambda r: accept(r) or r["state"] == "fault", what, timeout_s)
    assert accept(record), f"{what}: {record['state']}, faults {record['faults']}"
    return record


def enabled_at_rest(client: HexactlClient) -> dict:
    """Enable (once the actuators report) unless enabled; wait until at rest. A fault a
    starved guest latched in an earlier test is reset first, so each test starts from a
    known state (the fault itself is printed)."""

    def attempt() -> bool:
        record = client.call("status")["status"]
        if record["state"] in ("fault", "estop"):
            print(f"resetting a latched {record['state']} before the test: {record['faults']}")
            client.call("reset")
            return False
        try:
            client.call("enable")
        except CommandError as error:
            # actuators not heard from yet, an E-stop still clearing (they release it only
            # 250 ms after the last ESTOP frame), or a stall latched since the status: reset next
            assert error.code in ("heartbeat_missing", "actuator_fault", "latched"), error
            return False
        return True

    for tries in range(1, ENABLE_TRIES + 1):
        wait_for(attempt, "the actuators to enable")
        record = wait_status(client, lambda r: at_rest(r) or r["state"] in ("fault", "estop"), "the platform at rest")
        if at_rest(record) or tries == ENABLE_TRIES:
            break
        print(f"a {record['state']} latched while coming to rest, reset and enabled again: {record['faults']}")
    assert at_rest(record), record["faults"]
    return record


def test_serve_drives_the_six_actuators_on_vcan(service: Served, client: HexactlClient, nominal: Geometry) -> None:
    record = wait_status(client, lambda r: r["leg_feedback"] is not None and None not in r["leg_feedback"],
                         "feedback from all six actuators")  # fmt: skip
    assert record["calibration_id"] == geometry_id(nominal)
    assert record["loop"]["rate_hz"] == RATE_HZ
    with TelemetrySubscriber(service.telemetry) as telemetry:
        assert telemetry.receive(WAIT_S)["calibration_id"] == geometry_id(nominal)
    log = service.text()
    assert f"actuators: CAN {SPEC}" in log and f"control loop at {RATE_HZ} Hz" in log, log


# The tests that move run again from the start (tolerating_stalls) if a starved guest stopped
# the actuators by their watchdog, or the loop's supervision latched, on the way (every fault
# latched a stall's: tests/reliability/support.py); any other fault fails them.


def test_enable_move_and_the_measured_pose_follows(client: HexactlClient) -> None:
    def scenario() -> None:
        enabled_at_rest(client)
        goal = [0.0, 0.0, 20.0, 0.0, 0.0, 2.0]
        assert client.call("move", pose=goal, duration=1.0)["goal"] == pytest.approx(goal)
        record = wait_arrived(client, arrived, "the move to end")
        assert record["pose_command"] == pytest.approx(goal, abs=1e-6)
        assert record["pose_measured"] == pytest.approx(goal, abs=POSE_ABS)

    tolerating_stalls(client, scenario)


def test_play_a_built_in_sequence_to_the_end(client: HexactlClient, data_dir: Path) -> None:
    def scenario() -> None:
        enabled_at_rest(client)
        played = client.call("play", sequence="compound")
        assert (played["name"], played["waypoints"]) == ("compound", 2)
        record = wait_arrived(client, arrived, "the sequence to end", played["duration"] + WAIT_S)
        last = [100.0, 100.0, 100.0, 5.0, 5.0, 5.0]  # compound's last waypoint
        assert record["pose_command"] == pytest.approx(last, abs=1e-6)
        assert record["pose_measured"] == pytest.approx(last, abs=POSE_ABS)

    tolerating_stalls(client, scenario)
    saved = client.call("save_recording", path="compound.csv")
    assert (saved["name"], saved["status"], saved["records"]) == ("compound", "finished", 2)
    assert len((data_dir / "compound.csv").read_text().splitlines()) == 3


def test_leg_lock_keeps_the_locked_leg_while_the_others_move(client: HexactlClient) -> None:

    def scenario() -> None:
        start = enabled_at_rest(client)
        client.call("leg_lock", leg=3)
        locked = wait_status(client, lambda r: r["locked_leg"] == 3, "leg 3 locked")["leg_feedback"][2]
        moved = client.call("move", pose=[start["pose_command"][0] + 15.0, *start["pose_command"][1:]], duration=1.0)
        seen = []

        def settled(record: dict) -> bool:  # sampling the feedback during the move
            seen.append(record["leg_feedback"])
            return arrived(record)

        record = wait_arrived(client, settled, "the locked move to end")
        assert all(abs(feedback[2] - locked) <= SENSOR_STEP_MM for feedback in seen), [f[2] for f in seen]
        assert max(abs(a - b) for a, b in zip(record["leg_feedback"], start["leg_feedback"])) > 1.0  # the others moved
        assert record["pose_command"] == pytest.approx(moved["goal"], abs=1e-6)  # the goal projected onto the lock
        assert record["pose_measured"] == pytest.approx(moved["goal"], abs=POSE_ABS)
        client.call("leg_unlock")
        assert status(client)["locked_leg"] is None

    tolerating_stalls(client, scenario)


def call_again_if_stale(client: HexactlClient, cmd: str, **fields: object) -> dict:
    """``cmd``, sent once more if refused ``stale_plan`` (the loop's state moved while it
    was checked, as a starved guest's late cycles make likelier): what its message asks."""
    try:
        return client.call(cmd, **fields)
    except CommandError as error:
        if error.code != "stale_plan":
            raise
        print(f"{cmd}: {error}; sent again")
        return client.call(cmd, **fields)


def test_load_a_calibration_and_roll_it_back(client: HexactlClient, nominal: Geometry, data_dir: Path) -> None:
    joints = [list(joint) for joint in nominal.platform_joints]
    joints[0][0] += 1.0  # platform joint 1 identified 1 mm off its nominal x
    calibrated = Geometry.model_validate({**nominal.model_dump(), "name": "vcan test calibration", "platform_joints": joints})
    (data_dir / "cal.toml").write_text(geometry_to_toml(calibrated))

    def roll_back(to: Geometry) -> None:
        rolled = call_again_if_stale(client, "rollback_calibration")
        assert rolled["calibration_id"] == geometry_id(to)
        record = wait_arrived(client, lambda r: arrived(r) and r["calibration_id"] == geometry_id(to), "the rollback")
        assert record["pose_measured"] == pytest.approx(record["pose_command"], abs=POSE_ABS)

    def scenario() -> None:
        if enabled_at_rest(client)["calibration_id"] != geometry_id(nominal):
            roll_back(nominal)  # an attempt that a stall ended after the load
        loaded = call_again_if_stale(client, "load_calibration", path="cal.toml")
        # a joint 1 mm off changes its leg's length by at most 1 mm
        assert loaded["calibration_id"] == geometry_id(calibrated) and 0.0 < loaded["change_mm"] <= 1.0 + 1e-9
        record = wait_arrived(client, lambda r: arrived(r) and r["calibration_id"] == geometry_id(calibrated),
                              "the calibration to ramp in")  # fmt: skip
        assert record["pose_measured"] == pytest.approx(record["pose_command"], abs=POSE_ABS)
        roll_back(nominal)

    tolerating_stalls(client, scenario)


def test_estop_latches_until_reset(client: HexactlClient) -> None:
    for attempt in range(1, ATTEMPTS + 1):
        enabled_at_rest(client)
        client.call("estop")
        record = status(client)
        assert record["state"] == "estop", record
        besides = [fault for fault in record["faults"] if fault["code"] != "estop"]
        if not besides:
            break
        # A stall of the starved guest latched the actuators' watchdog just before the E-stop
        # (CI: 3 s before it): what the service must do, not what this tests. Again, from the
        # reset enabled_at_rest makes.
        print(f"attempt {attempt}: besides the E-stop, latched: {besides}")
        assert attempt < ATTEMPTS and all(map(is_stall, besides)), record["faults"]
    with pytest.raises(CommandError, match="latched"):
        client.call("enable")
    client.call("reset")

    def reset_done(record: dict) -> bool:
        # An actuator refuses CLEAR_FAULT while it saw an E-stop within its hold-off; in a
        # starved guest the loop's last E-stop repeats reach it late, the refusal leaves it in
        # E-stop and the loop latches that again. The operator resets once more (as
        # tests/reliability/support.py's enable does for a refused CLEAR_FAULT).
        if record["state"] == "estop" and [fault["message"] for fault in record["faults"]] == [ACTUATOR_ESTOP]:
            client.request("reset")
            time.sleep(RESET_RETRY_S)
        return record["state"] == "disabled"

    wait_status(client, reset_done, "the reset")
    record = enabled_at_rest(client)  # the actuators come back after the E-stop
    assert record["faults"] == []


def test_sigterm_disables_the_actuators_and_no_frame_was_rejected(service: Served, simulator: subprocess.Popen) -> None:
    terminate_simulator(simulator, tolerate_watchdog=terminate_service(service))
