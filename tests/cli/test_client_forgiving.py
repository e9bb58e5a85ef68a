"""The client command line as a new user meets it (hexactl issue 16): local calibration
files sent, relative recording names, negative poses, "did you mean", ``--version``,
``--speed`` checked, a closed pipe, endpoints set once, shell completion. Against a
service with a fake controller on random local ports (tests/api/support.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path
from types import SimpleNamespace

import pytest

from hexactl.adapters.api.commands import TOML_SOURCE
from hexactl.adapters.cli import main as main_module
from hexactl.adapters.cli.common import DASH_HINT
from hexactl.adapters.cli.main import EXIT_BROKEN_PIPE, main
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry
from hexactl.kinematics.geometry import Geometry
from tests.api.support import start_service
from tools.serving import unserved_endpoint

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 120.0  # only turns a hang into a failure


@pytest.fixture(scope="module")
def nominal() -> Geometry:
    return load_geometry(default_config_path())


@pytest.fixture
def service(nominal: Geometry, tmp_path: Path) -> Iterator[SimpleNamespace]:
    """A fake controller's service whose data directory is ``tmp_path/data`` (the endpoint
    settings of the machine running the tests are none: tests/conftest.py)."""
    (tmp_path / "data").mkdir()
    running = start_service(nominal, tmp_path / "data")
    yield running
    running.close()


def run(service: SimpleNamespace, command: str, *arguments: str) -> int:
    return main([command, "--api", service.api, *arguments])


def hexactl(*arguments: str, env: dict[str, str] | None = None,
            stdout: int = subprocess.PIPE) -> subprocess.CompletedProcess[str]:
    """``hexactl ARGUMENTS`` in a fresh interpreter on this tree, with ``env`` added to
    the environment."""
    return subprocess.run([sys.executable, "-m", "hexactl.adapters.cli.main", *arguments], stdout=stdout,
                          stderr=subprocess.PIPE, text=True, timeout=TIMEOUT_S,
                          env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


# -- 1. load-calibration of a file here --------------------------------------------------


def test_a_calibration_file_here_is_sent_with_its_name(service, nominal, tmp_path, monkeypatch, capsys) -> None:
    calibrated = nominal.model_copy(update={"name": "demo"})
    (tmp_path / "demo-out").mkdir()
    (tmp_path / "demo-out" / "calibration.toml").write_text(geometry_to_toml(calibrated))
    monkeypatch.chdir(tmp_path)  # outside the service's data directory, as the README's demo-out is
    assert run(service, "load-calibration", "demo-out/calibration.toml") == 0
    where = tmp_path / "demo-out" / "calibration.toml"
    assert capsys.readouterr().out.strip() == (f"ok: calibration {geometry_id(calibrated)} loaded; read from {where} "
                                               "here and sent; set-points change by up to 0.500 mm")
    assert service.controller.calls[-1][1][2] == f"{TOML_SOURCE} ({where})"  # the service records which file
    assert run(service, "load-calibration", "--send", "demo-out/calibration.toml") == 0  # still accepted


@pytest.mark.parametrize("comment_bytes", [100_000, 2_000_000])
def test_a_calibration_too_large_to_send_goes_by_its_path(service, nominal, tmp_path, monkeypatch, capsys,
                                                          comment_bytes) -> None:
    """Found from outside: a calibration with 68 KB of comments was refused too_large with no
    way out, and one of 2 MB got "no answer within 5 s: is hexactl serve running there?".
    Too large for a request, the file goes by its path: read by the service from its data
    directory, and refused naming them from elsewhere."""
    text = geometry_to_toml(nominal.model_copy(update={"name": "padded"})) + ("# history\n" * (comment_bytes // 10))
    (service.data_dir / "padded.toml").write_text(text)
    (tmp_path / "elsewhere.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    assert run(service, "load-calibration", str(service.data_dir / "padded.toml")) == 0, capsys.readouterr().err
    assert service.controller.calls[-1][0] == "load_calibration"
    capsys.readouterr()
    assert run(service, "load-calibration", "elsewhere.toml") == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error forbidden_path: {tmp_path / 'elsewhere.toml'}: outside the data directories"), err
    assert run(service, "load-calibration", "--send", "elsewhere.toml") == 2
    assert "too large to send" in capsys.readouterr().err


def test_malformed_toml_is_refused_here_naming_the_file(service, tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    Path("bad.toml").write_text("zero_lengths = [1,\n")
    assert run(service, "load-calibration", "bad.toml") == 2
    err = capsys.readouterr().err
    assert err.startswith("hexactl load-calibration: error: bad.toml: not valid TOML: ")
    assert "(at line 1" in err or "(at end of document)" in err
    assert not any(name == "load_calibration" for name, _ in service.controller.calls)  # nothing was sent


def test_a_name_not_here_goes_to_the_service_and_its_refusal_lists_the_data_directories(service, capsys) -> None:
    assert run(service, "load-calibration", "cal.toml") == 1
    err = capsys.readouterr().err
    assert err.startswith("error file_not_found: cal.toml: no such file in the data directories")
    assert f"the service's data directories: {service.data_dir.resolve()}" in err
    assert "a relative name is looked up in each data directory" in err
    assert run(service, "load-calibration", "/nowhere/cal.toml") == 1
    err = capsys.readouterr().err
    assert err.startswith("error forbidden_path: /nowhere/cal.toml: outside the data directories")
    assert f"the service's data directories: {service.data_dir.resolve()}" in err
    assert "hexactl serve --data-dir DIR" in err


# -- 2. save-recording's relative names ------------------------------------------------


def test_a_bare_recording_name_goes_into_the_first_data_directory(service, tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)  # not the data directory: the name must not be made absolute here
    assert run(service, "play", "x_sweep") == 0
    assert run(service, "save-recording", "run2.csv") == 0
    assert (service.data_dir / "run2.csv").is_file()
    assert f"written to {(service.data_dir / 'run2.csv').resolve()}" in capsys.readouterr().out


def test_a_recording_path_into_a_data_directory_here_is_written_there(service, tmp_path, monkeypatch) -> None:
    """The README's ``save-recording recordings/run1.csv`` with the service started in the
    same working directory: here the data directory is ``data``."""
    monkeypatch.chdir(tmp_path)
    assert run(service, "play", "x_sweep") == 0
    assert run(service, "save-recording", "data/run1.csv") == 0
    assert (service.data_dir / "run1.csv").is_file()


# -- 3. the projected goal: test_real_service.py -----------------------------------------
# -- 4. negative poses -----------------------------------------------------------------


def test_a_negative_pose_needs_no_double_dash(service, capsys) -> None:
    service.controller.state = "enabled"
    assert run(service, "move", "-10,0,-5.5,0,0,-1e1") == 0
    assert service.controller.calls[-1] == ("move", ([-10.0, 0.0, -5.5, 0.0, 0.0, -10.0], None, None))
    assert main(["move", "-10,0,0,0,0,0", "--api", service.api, "--speed", "0.5"]) == 0  # options after it too
    assert service.controller.calls[-1] == ("move", ([-10.0, 0.0, 0.0, 0.0, 0.0, 0.0], None, 0.5))


def test_options_after_double_dash_are_explained(service, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["move", "--", "-10,0,0,0,0,0", "--api", service.api])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert f"unrecognized arguments: --api {service.api}" in err
    assert "options go before `--`: everything after it is read as values" in err


def test_a_value_misread_as_an_option_hints_at_double_dash(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["move", "-10,0,0,0,0,yaw"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "the following arguments are required: POSE" in err
    assert DASH_HINT in err


# -- 5. did you mean, --version ----------------------------------------------------------


def test_a_mistyped_command_gets_did_you_mean(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["enabel"])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'enabel'" in err
    assert err.rstrip().endswith("did you mean 'enable'?")


def test_version() -> None:
    result = hexactl("--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"hexactl {version('hexactl')}\n"


# -- 6. --speed ------------------------------------------------------------------------


@pytest.mark.parametrize("speed", ["2", "0", "-0.5", "nan"])
def test_speed_outside_zero_one_is_bad_input(speed, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["move", "x=5", "--speed", speed])
    assert exited.value.code == 2
    assert f"argument --speed: '{speed}' must be a fraction in (0, 1] of the velocity limits" in capsys.readouterr().err


# -- 7. a closed pipe ------------------------------------------------------------------


def test_a_closed_pipe_ends_quietly() -> None:
    """``hexactl … | head`` once head has gone: no traceback, the status of SIGPIPE."""
    reading, writing = os.pipe()
    os.close(reading)  # every write to the pipe fails: EPIPE
    try:
        result = hexactl("ik", "0", "0", "0", "0", "0", "0", stdout=writing)
    finally:
        os.close(writing)
    assert result.returncode == EXIT_BROKEN_PIPE
    assert result.stderr == ""


# -- 10. endpoints set once ------------------------------------------------------------


def test_the_api_endpoint_from_the_environment_and_status_says_so(service, monkeypatch, capsys) -> None:
    monkeypatch.setenv("HEXACTL_API", service.api)
    assert main(["status"]) == 0
    assert capsys.readouterr().out.startswith(f"service        {service.api} (from HEXACTL_API)\n")


def test_the_api_endpoint_from_the_client_file(service, tmp_path, monkeypatch, capsys) -> None:
    client_file = tmp_path / "client.toml"
    client_file.write_text(f'api = "{service.api}"\n')
    monkeypatch.setenv("HEXACTL_CLIENT_CONFIG", str(client_file))
    assert main(["status"]) == 0
    assert capsys.readouterr().out.startswith(f"service        {service.api} (from {client_file})\n")
    monkeypatch.setenv("HEXACTL_API", unserved_endpoint())  # the flag wins over both
    assert main(["status", "--api", service.api]) == 0
    assert capsys.readouterr().out.startswith(f"service        {service.api} (from --api)\n")


def test_the_telemetry_endpoint_from_the_environment(service, monkeypatch, capsys) -> None:
    monkeypatch.setenv("HEXACTL_TELEMETRY", service.telemetry)
    assert main(["monitor", "--once", "--timeout", "30"]) == 0
    assert "disabled" in capsys.readouterr().out


def test_the_campaign_takes_its_endpoint_from_the_environment_too(monkeypatch, tmp_path, capsys) -> None:
    nobody = unserved_endpoint()
    monkeypatch.setenv("HEXACTL_API", nobody)  # nobody there: the error names where it asked
    assert main(["campaign", "--out", str(tmp_path / "campaign"), "--timeout", "0.2"]) != 0
    assert nobody in capsys.readouterr().err


def test_a_bad_client_file_is_named(service, tmp_path, monkeypatch, capsys) -> None:
    client_file = tmp_path / "client.toml"
    client_file.write_text('apy = "tcp://127.0.0.1:5555"\n')
    monkeypatch.setenv("HEXACTL_CLIENT_CONFIG", str(client_file))
    assert main(["status"]) == 2
    assert capsys.readouterr().err.strip() == (f"hexactl status: error: {client_file}: unknown key apy; the client "
                                               "file knows api, curve_client, curve_server, telemetry")


@pytest.mark.parametrize(("content", "said"), [
    (None, "no such file: check the name, or unset HEXACTL_CLIENT_CONFIG to use $XDG_CONFIG_HOME/hexactl/client.toml"),
    ("", "the file names no setting; give at least one of api, curve_client, curve_server, telemetry"),
    ("# only a comment\n", "the file names no setting"),
])
def test_a_client_file_named_but_missing_or_empty_is_refused_not_passed_over(content, said, tmp_path, monkeypatch,
                                                                              capsys) -> None:
    """Found from outside: a HEXACTL_CLIENT_CONFIG naming a file not there (a typo) or empty
    was passed over, and move, enable … went to the default endpoint: another service, perhaps."""
    client_file = tmp_path / "client.toml"
    if content is not None:
        client_file.write_text(content)
    monkeypatch.setenv("HEXACTL_CLIENT_CONFIG", str(client_file))
    assert main(["enable", "--timeout", "0.2"]) == 2
    error = capsys.readouterr().err
    assert f"HEXACTL_CLIENT_CONFIG={client_file}: {said}" in error and "no answer" not in error, error


def test_without_settings_the_default_endpoint(service, monkeypatch, capsys) -> None:
    assert main(["status", "--timeout", "0.2"]) in (0, 2)  # whether or not a service runs on the default port
    captured = capsys.readouterr()
    assert "tcp://127.0.0.1:5555" in captured.out + captured.err


# -- 11. shell completion --------------------------------------------------------------


def test_the_argcomplete_marker_is_where_argcomplete_looks() -> None:
    assert "PYTHON_ARGCOMPLETE_OK" in Path(main_module.__file__).read_bytes()[:1024].decode()


def test_shell_completion_of_a_command(tmp_path) -> None:
    out = tmp_path / "completions"
    line = "hexactl ena"
    result = hexactl(env={"_ARGCOMPLETE": "1", "COMP_LINE": line, "COMP_POINT": str(len(line)),
                          "_ARGCOMPLETE_STDOUT_FILENAME": str(out), "_ARGCOMPLETE_IFS": "\n"})
    assert result.returncode == 0, result.stderr
    assert out.read_text().split() == ["enable"]


# -- 8. a network bind without CURVE -----------------------------------------------------


def test_a_network_bind_without_curve_is_refused_before_any_word_of_curve(caplog, capsys) -> None:
    assert main(["serve", "--api", "tcp://0.0.0.0:*", "--telemetry", "tcp://127.0.0.1:*"]) == 2
    assert not any("reachable from the network" in record.getMessage() for record in caplog.records)
    err = capsys.readouterr().err
    assert "refusing to bind tcp://0.0.0.0:* without CURVE" in err
    assert "hexactl keys --out DIR" in err and "--curve-secret" in err
