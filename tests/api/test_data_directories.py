"""``hexactl serve``'s data directories: the default ones created with the example
sequences in ./sequences, given ones that must exist; and every shipped example valid on
the nominal platform."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.cli.main import main
from hexactl.adapters.files.config_path import default_config_path
from hexactl.adapters.files.sequence_file import sequence_from_toml
from hexactl.application.service import (
    EXAMPLE_SEQUENCES,
    ServiceError,
    data_directories,
)
from tests.api.test_service import at_rest, wait_for
from tests.control.conftest import Rig
from tools.serving import serve, terminate

EXAMPLES = sorted(entry.name for entry in EXAMPLE_SEQUENCES.iterdir() if entry.name.endswith(".toml"))
WAIT_S = 30.0  # generous: the simulator and the loop share a possibly busy machine


def test_examples_are_shipped() -> None:
    assert len(EXAMPLES) >= 2, EXAMPLES


@pytest.mark.parametrize("name", EXAMPLES)
def test_every_example_validates_on_the_nominal_platform(nominal, name) -> None:
    sequence = sequence_from_toml((EXAMPLE_SEQUENCES / name).read_text(), name)
    assert f"{sequence.name}.toml" == name  # `play NAME.toml` plays the sequence NAME
    result = Rig(nominal).controller.validate_sequence(sequence)
    assert result.ok, f"{name}: {result.message}"
    assert result.details["waypoints"] == len(sequence.waypoints)


def test_default_directories_are_created_with_the_examples(tmp_path, monkeypatch, caplog) -> None:
    monkeypatch.chdir(tmp_path)
    config = default_config_path()
    with caplog.at_level(logging.INFO, logger="hexactl.service"):
        directories = data_directories(None, config)
    assert directories == (tmp_path / "recordings", tmp_path / "calibrations", tmp_path / "sequences",
                           config.resolve().parent)
    assert all(directory.is_dir() for directory in directories)
    assert sorted(path.name for path in (tmp_path / "sequences").iterdir()) == EXAMPLES
    for name in ("recordings", "calibrations", "sequences"):
        assert f"created data directory {tmp_path / name}" in caplog.text
    assert f"example sequences in {tmp_path / 'sequences'}: {', '.join(EXAMPLES)}" in caplog.text


def test_existing_directories_and_files_are_left_as_they_are(tmp_path, monkeypatch, caplog) -> None:
    """Nothing overwritten, nothing put back that the operator removed or changed."""
    monkeypatch.chdir(tmp_path)
    data_directories(None, default_config_path())
    mine = tmp_path / "sequences" / EXAMPLES[0]
    mine.write_text("name = 'mine'\n")
    (tmp_path / "sequences" / EXAMPLES[1]).unlink()
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="hexactl.service"):
        data_directories(None, default_config_path())
    assert mine.read_text() == "name = 'mine'\n"
    assert not (tmp_path / "sequences" / EXAMPLES[1]).exists()
    assert "created" not in caplog.text and "example" not in caplog.text


def test_a_file_in_the_way_of_a_default_directory_is_refused(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "recordings").write_text("not a directory")
    with pytest.raises(ServiceError, match=rf"data directory {tmp_path / 'recordings'}: exists but is not a "
                                           "directory; move it away, or give --data-dir"):
        data_directories(None, default_config_path())


def test_given_directories_must_exist(tmp_path) -> None:
    """A mistyped --data-dir is refused, not created where nobody will look."""
    (tmp_path / "data").mkdir()
    assert data_directories((tmp_path / "data",), default_config_path()) == (tmp_path / "data",)
    with pytest.raises(ServiceError, match=rf"data directory {tmp_path / 'dta'}: no such directory; create it, or "
                                           "correct --data-dir"):
        data_directories((tmp_path / "data", tmp_path / "dta"), default_config_path())
    assert not (tmp_path / "dta").exists()


def test_serve_refuses_a_missing_data_dir_naming_it(tmp_path) -> None:
    finished = subprocess.run([sys.executable, "-m", "hexactl.adapters.cli.main", "serve", "--api", "tcp://127.0.0.1:*",
                               "--telemetry", "tcp://127.0.0.1:*", "--data-dir", "nowhere"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False)
    assert finished.returncode != 0
    assert "data directory nowhere: no such directory; create it, or correct --data-dir" in finished.stderr
    assert not (tmp_path / "nowhere").exists()


def test_a_start_refused_at_the_bus_leaves_no_directory_behind(tmp_path) -> None:
    """The default directories are made last before the API: a start that fails earlier
    (here a bus that cannot be opened) leaves none in the working directory."""
    finished = subprocess.run([sys.executable, "-m", "hexactl.adapters.cli.main", "serve", "--api", "tcp://127.0.0.1:*",
                               "--telemetry", "tcp://127.0.0.1:*", "--no-realtime", "--can", "socketcan:hexactl-none0"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False)
    assert finished.returncode != 0
    assert "cannot open the actuators' bus socketcan:hexactl-none0" in finished.stderr
    # the kept files' hidden locks stay, as after every run (docs: service_lock)
    assert sorted(path.name for path in tmp_path.iterdir() if not path.name.startswith(".")) == []


def test_serve_creates_the_directories_and_plays_an_example_and_a_plan(tmp_path, capsys) -> None:
    """The operator's first steps in an empty directory: serve, play a shipped example,
    play a plan written by plan-leglock into ./sequences, save the recording."""
    from tests.reliability.support import recover

    assert main(["plan-leglock", "--leg", "2", "--count", "3", "-o", str(tmp_path / "plan.csv")]) == 0
    with serve(tmp_path) as served:
        assert sorted(path.name for path in (tmp_path / "sequences").iterdir()) == EXAMPLES
        assert (tmp_path / "recordings").is_dir() and (tmp_path / "calibrations").is_dir()
        (tmp_path / "plan.csv").rename(tmp_path / "sequences" / "plan.csv")
        with HexactlClient(served.api, timeout_s=WAIT_S) as client:
            recover(client)
            played = client.call("play", sequence=EXAMPLES[0])
            assert played["ok"] and played["name"] == Path(EXAMPLES[0]).stem, played
            client.call("abort")
            wait_for(lambda: at_rest(client), "the platform at rest after the abort")
            plan = client.call("play", sequence="plan.csv")
            assert plan["ok"] and (plan["name"], plan["waypoints"]) == ("plan", 3), plan
            client.call("abort")
            saved = client.call("save_recording", path="run1.csv")
            assert saved["ok"] and Path(saved["path"]) == tmp_path / "recordings" / "run1.csv", saved
        assert main(["play", "x_swep", "--api", served.api]) != 0
        assert "did you mean 'x_sweep'?" in capsys.readouterr().err
        shutdown = terminate(served)
    assert shutdown.problems() == [], served.log
    for name in ("recordings", "calibrations", "sequences"):
        assert f"created data directory {tmp_path / name}" in served.log
