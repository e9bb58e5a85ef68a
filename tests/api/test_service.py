"""The whole service: geometry → CAN link → six simulated actuators on an in-process bus →
controller → API and telemetry, in-process; and ``hexactl serve`` as a process that
shuts down cleanly on SIGTERM."""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient, TelemetrySubscriber
from hexactl.adapters.api.messages import StatusReply, Telemetry
from hexactl.adapters.api.security import CurveServerKeys, SecurityError, create_keys
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.application.service import Service, ServiceConfig, ServiceError, main_thread_below_loop
from tools.serving import serve, terminate, wait_until

WAIT_S = 30.0  # generous: the simulator and the loop share a possibly busy machine

wait_for = functools.partial(wait_until, timeout_s=WAIT_S, poll_s=0.02)
"""The wait of these tests and of those that import it (tests/reliability)."""


@pytest.fixture
def client(running) -> Iterator[HexactlClient]:
    with HexactlClient(running.api_endpoint, timeout_s=WAIT_S) as client:
        yield client


def status(client: HexactlClient) -> dict:
    reply = client.call("status")
    StatusReply.model_validate(reply)  # the real controller's telemetry fits the documented model
    return reply["status"]


def at_rest(client: HexactlClient) -> dict | None:
    """The status record once the platform is at rest with no sequence playing, else None.
    AssertionError at once if a fault or E-stop latched instead: the platform is at rest
    then too, but held wherever the fault caught it."""
    record = status(client)
    assert record["state"] == "enabled", f"{record['state']} latched: {record['faults']}"
    return record if record["motion"] == "holding" and record["sequence"] is None else None


def test_status_names_the_active_geometry(client, nominal) -> None:
    record = status(client)
    assert record["calibration_id"] == geometry_id(nominal)
    assert record["loop"]["rate_hz"] == 500.0
    assert record["leg_feedback"] is not None


def test_telemetry_records_from_the_real_controller(running) -> None:
    with TelemetrySubscriber(running.telemetry_endpoint) as telemetry:
        record = Telemetry.model_validate(telemetry.receive(WAIT_S))
    assert record.state in ("disabled", "enabled")


def test_move_play_record_estop_reset(running, client, data_dir) -> None:
    """The motion commands through the whole service. On a loaded host the loop can be
    held up past the simulated actuators' watchdog, which then stops the platform (all
    six latch COMM_TIMEOUT): such an attempt is run again, at most three in all; any
    other failure fails (``tolerating_loop_stalls``, docs/reliability.md)."""
    # tests.reliability.support builds on this module's helpers: imported once both are loaded.
    from tests.reliability.support import recover, tolerating_loop_stalls

    goal = [0, 0, 20, 0, 0, 2]
    recording = data_dir / "hop.csv"

    def scenario() -> None:
        recover(client)  # enabled (waiting for the actuators to boot) and at rest, whatever an attempt left
        moved = client.call("move", pose=goal, duration=0.5)
        assert moved["goal"] == pytest.approx(goal)
        record = wait_for(lambda: at_rest(client), "the move to end")
        assert record["pose_command"] == pytest.approx(goal, abs=1e-6)
        # The feedback trails the last set-points by a few cycles, more on a loaded host: wait for it.
        wait_for(lambda: at_rest(client)["pose_measured"] == pytest.approx(goal, abs=0.05),  # 1 µm sensor steps
                 "the measured pose to reach the goal")

        sequence = {"name": "hop", "waypoints": [{"pose": [0, 0, 10, 0, 0, 0], "dwell": 0.05}, {"pose": [0] * 6, "dwell": 0.05}]}
        played = client.call("play", sequence=sequence)
        assert (played["name"], played["waypoints"]) == ("hop", 2)
        wait_for(lambda: at_rest(client), "the sequence to end")
        saved = client.call("save_recording", path=recording.name)
        assert (saved["name"], saved["status"], saved["records"]) == ("hop", "finished", 2)
        assert len(recording.read_text().splitlines()) == 3

        refused = client.request("move", pose=[700, 0, 0, 0, 0, 0])
        assert refused["error"]["code"] == "path_violation"
        assert refused["error"]["details"]["violations"][0]["axis"] == "x"

        client.call("estop")
        assert status(client)["state"] == "estop"
        assert client.request("enable")["error"]["code"] == "latched"
        reset = client.call("reset")
        assert reset["message"] == "reset to disabled" and status(client)["state"] == "disabled", reset
        # At once: the reset's reply comes once the actuators have left E-stop. It came before,
        # and an enable right after was refused actuator_fault ("enable again shortly").
        client.call("enable")

    # A failed attempt's recording would make the next one's save_recording file_exists.
    tolerating_loop_stalls(scenario, lambda: running.controller, cleanup=lambda: recording.unlink(missing_ok=True))


def test_non_loopback_bind_without_curve_is_refused_before_anything_starts() -> None:
    with pytest.raises(SecurityError, match="without CURVE"):
        Service.start(ServiceConfig(api_endpoint="tcp://0.0.0.0:*", telemetry_endpoint="tcp://127.0.0.1:*"))


def test_a_network_stream_socket_without_curve_is_refused_too() -> None:
    """Found from outside: ``--stream tcp://*:5557`` beside a loopback API started without a
    word, and anyone on the network could steer the platform while a stream was open."""
    with pytest.raises(SecurityError, match=r"refusing to bind tcp://\*:\* without CURVE"):
        Service.start(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    stream_endpoint="tcp://*:*"))


def test_serve_command_refuses_a_network_bind_without_keys(capsys) -> None:
    assert main(["serve", "--api", "tcp://*:5555"]) == 2
    assert "refusing to bind tcp://*:5555 without CURVE" in capsys.readouterr().err


def test_serve_starts_with_a_calibration(nominal, tmp_path) -> None:
    calibrated = nominal.model_copy(update={"name": "calibrated", "zero_lengths": (1750.5,) * 6})
    path = tmp_path / "cal.toml"
    path.write_text(geometry_to_toml(calibrated))
    service = Service.start(ServiceConfig(calibration_path=path, api_endpoint="tcp://127.0.0.1:*",
                                          telemetry_endpoint="tcp://127.0.0.1:*"))
    try:
        with HexactlClient(service.api_endpoint) as client:
            assert status(client)["calibration_id"] == geometry_id(calibrated)
    finally:
        service.close()


def test_a_program_that_starts_a_service_keeps_its_threads_scheduling(tmp_path) -> None:
    """Only the service's own threads become real-time: the caller's thread may run
    anything (here pytest); ``main_thread_below_loop`` is for processes the service owns."""
    before = os.sched_getscheduler(0), os.sched_getparam(0)  # this module's service (running) may have raised it
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    policy = os.sched_getscheduler(0)
    service = Service.start(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                          data_dirs=(tmp_path,)))
    try:
        assert os.sched_getscheduler(0) == policy
        loop_priority = service.controller.thread.loop.realtime.fifo_priority
        main_thread_below_loop(service)
        if loop_priority is None:  # no privilege for real time here: nothing changes
            assert os.sched_getscheduler(0) == policy
        else:
            assert os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == loop_priority - 1
    finally:
        os.sched_setscheduler(0, *before)
        service.close()


def test_bad_server_key_is_refused_before_the_actuators_open(tmp_path) -> None:
    keys = create_keys(tmp_path)
    curve = CurveServerKeys(keys["server_public"], keys["clients_dir"])  # the public half: no secret key
    with pytest.raises(ServiceError, match="no secret key"):
        Service.start(ServiceConfig(api_endpoint="tcp://0.0.0.0:*", telemetry_endpoint="tcp://127.0.0.1:*", curve=curve))


def test_endpoint_in_use_is_refused_and_everything_closes(running) -> None:
    with pytest.raises(ServiceError, match="cannot serve"):
        Service.start(ServiceConfig(api_endpoint=running.api_endpoint, telemetry_endpoint="tcp://127.0.0.1:*"))


@pytest.mark.parametrize("taken", ["api", "telemetry"])
def test_endpoint_in_use_is_refused_before_the_actuators_open(taken, running, monkeypatch) -> None:
    """A second service on a running one's ports used to open the actuators' bus and run
    its loop (sending on the bus beside the first) until its API process failed to bind."""
    def opened(*arguments: object, **options: object) -> None:
        pytest.fail("the actuators were opened")

    monkeypatch.setattr("hexactl.application.service.Simulator", opened)
    endpoints = {"api_endpoint": "tcp://127.0.0.1:*", "telemetry_endpoint": "tcp://127.0.0.1:*",
                 f"{taken}_endpoint": getattr(running, f"{taken}_endpoint")}
    with pytest.raises(ServiceError) as refused:
        Service.start(ServiceConfig(**endpoints))
    # It said only "cannot serve: Address already in use (addr=…)": not which option, nor what to do.
    taken_endpoint = endpoints[f"{taken}_endpoint"]
    assert str(refused.value) == (f"--{taken}: cannot serve: {taken_endpoint}: another process serves there (another "
                                  "hexactl serve?): stop it first, or name another port (tcp://HOST:* takes a free one)")


@pytest.mark.parametrize(("api", "telemetry", "stream"), [
    ("tcp://127.0.0.1:56999", "tcp://127.0.0.1:56999", None),
    ("tcp://127.0.0.1:56999", "tcp://*:56999", None),
    ("tcp://127.0.0.1:*", "tcp://localhost:56999", "tcp://127.0.0.1:56999"),
    ("ipc:///tmp/hexactl-clash", "tcp://127.0.0.1:*", "ipc:///tmp/hexactl-clash"),
])
def test_two_options_on_one_address_are_refused_naming_both(api, telemetry, stream, monkeypatch) -> None:
    """It said "cannot serve: Address already in use", as if another process held the port."""
    monkeypatch.setattr("hexactl.application.service.Simulator", lambda *a, **k: pytest.fail("the actuators opened"))
    with pytest.raises(ServiceError, match=r"take the same address: give each its own port"):
        Service.start(ServiceConfig(api_endpoint=api, telemetry_endpoint=telemetry, stream_endpoint=stream))


@pytest.mark.parametrize(("first", "second", "clash"), [
    ("tcp://127.0.0.1:5555", "tcp://127.0.0.1:5556", False),
    ("tcp://127.0.0.1:*", "tcp://127.0.0.1:*", False),
    ("tcp://10.0.0.1:5555", "tcp://10.0.0.2:5555", False),
    ("tcp://10.0.0.1:5555", "tcp://0.0.0.0:5555", True),
    ("tcp://localhost:5555", "tcp://127.0.0.1:5555", True),
    ("tcp://[::1]:5555", "tcp://127.0.0.1:5555", False),  # two address families
    ("ipc:///tmp/a", "ipc:///tmp/b", False),
    ("ipc:///tmp/a", "tcp://127.0.0.1:5555", False),
])
def test_endpoints_clash_on_one_address_only(first: str, second: str, clash: bool) -> None:
    from hexactl.adapters.api.protocol import endpoints_clash

    assert endpoints_clash(first, second) is clash and endpoints_clash(second, first) is clash


def test_bad_geometry_is_refused(tmp_path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("zero_lengths = [1]\n")
    with pytest.raises(ServiceError, match="bad.toml"):
        Service.start(ServiceConfig(config_path=bad, api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*"))


def test_serve_process_logs_and_shuts_down_on_sigterm(tmp_path: Path, capsys) -> None:
    from tests.reliability.support import STALL_FAULTS, recover  # here, as in test_move_play_record_estop_reset

    with serve(tmp_path) as served:
        assert main(["status", "--api", served.api, "--timeout", str(WAIT_S)]) == 0
        printed = capsys.readouterr().out  # where the calibration in force came from, beside its id
        assert re.search(r"^calibration +[0-9a-f]{16} \(from \S+\.toml\)$", printed, re.M), printed
        with HexactlClient(served.api, timeout_s=WAIT_S) as client:
            recover(client)
        assert main(["monitor", "--once", "--telemetry", served.telemetry, "--timeout", str(WAIT_S)]) == 0
        assert "state          enabled, holding" in capsys.readouterr().out
        shutdown = terminate(served)
    text = served.log
    assert shutdown.problems() == [], f"{shutdown}\n{text}"
    # Enabled at the SIGTERM, the service disables the actuators; a loop held up by a busy
    # host past its supervision latches a stall's fault first, and then there is nothing to disable.
    stalled = re.search(r"fault \((.*)\) at .*: nothing to brake", text)
    if stalled:
        watchdog = "faults: comm_timeout (0x1)"
        assert all(fault.split(":")[0] in STALL_FAULTS or fault.endswith(watchdog)
                   for fault in stalled[1].split("; ")), text
    for expected in ("nominal geometry 'hexactl nominal 1500/900'", "no calibration", "actuators: six simulated",
                     f"API on {served.api}", "SIGTERM: shutting down", "nothing to brake" if stalled else
                     "actuators disabled", "stopped"):
        assert expected in text, text


def test_serve_refuses_a_calibration_with_other_limits(tmp_path):
    from hexactl.adapters.files.geometry_file import load_geometry, save_geometry
    from hexactl.adapters.files.config_path import default_config_path
    from hexactl.application.service import Service, ServiceConfig, ServiceError

    nominal = load_geometry(default_config_path())
    data = nominal.model_dump()
    data["limits"]["leg_velocity_mm_s"] = 2 * nominal.limits.leg_velocity_mm_s
    fast = save_geometry(type(nominal).model_validate(data), tmp_path / "fast.toml")
    with pytest.raises(ServiceError, match=r"fast.toml: .*leg_velocity_mm_s: 800.0 \(hardware: 400.0\)"):
        Service.start(ServiceConfig(calibration_path=fast, api_endpoint="tcp://127.0.0.1:0",
                                    telemetry_endpoint="tcp://127.0.0.1:0"))
