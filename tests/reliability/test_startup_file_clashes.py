"""``hexactl serve`` refuses, before it touches anything, files it would destroy: one file
named by two of its options (the kept calibration removed as "nothing to keep" because it
was also the ``--config`` geometry), and a kept file that is a symbolic link to nothing
(an unmounted disk: started on the nominal geometry, or without the operator's soft
limits, the link removed)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from hexactl.adapters.cli.main import main
from hexactl.adapters.files.config_path import default_config_path
from hexactl.application import service
from hexactl.application.service import Service, ServiceConfig, ServiceError
from tests.reliability.support import LOCAL

FRAMES_TEXT = "work = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\ntool = [0.0, 0.0, 300.0, 0.0, 0.0, 0.0]\n\n" \
              "[soft_limits]\nmax_tilt_deg = 5.0\n"


def _config(data_dir: Path, **files: Path) -> ServiceConfig:
    return ServiceConfig(api_endpoint=LOCAL, telemetry_endpoint=LOCAL, data_dirs=(data_dir,), log_level="WARNING",
                         **files)


def _refusal(config: ServiceConfig) -> str:
    """Why ``config`` is refused; the test fails (the service stopped again) if it starts."""
    try:
        started = Service.start(config)
    except ServiceError as error:
        return str(error)
    started.close()
    pytest.fail("the service started")


def _contents(directory: Path) -> dict[str, str]:
    """Every name in ``directory`` (lock files too) with what it holds or links to."""
    return {path.name: (f"-> {os.readlink(path)}" if path.is_symlink() else path.read_text())
            for path in directory.iterdir() if not path.is_dir()}


@pytest.fixture
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working directory holding a geometry file, cal.toml, and frames.toml."""
    monkeypatch.chdir(tmp_path)
    shutil.copyfile(default_config_path(), tmp_path / "cal.toml")
    (tmp_path / "frames.toml").write_text(FRAMES_TEXT)
    (tmp_path / "data").mkdir()
    return tmp_path


# -- one file, two options -----------------------------------------------------------


def test_the_config_file_as_the_default_kept_calibration_is_refused_and_kept(here: Path) -> None:
    """``cp cal.toml active_calibration.toml; hexactl serve --config active_calibration.toml``
    restored it as the calibration in force, found it nominal, and deleted it."""
    shutil.copyfile(here / "cal.toml", here / "active_calibration.toml")
    before = _contents(here)
    refusal = _refusal(_config(here / "data", config_path=Path("active_calibration.toml")))
    assert refusal == (
        f"--config active_calibration.toml and --keep-calibration (default {here / 'active_calibration.toml'}) name "
        f"the same file, {here / 'active_calibration.toml'}: the service rewrites or removes --keep-calibration's file "
        "to keep the calibration in force for a restart, and would destroy the nominal geometry in it; give "
        "--keep-calibration a file of its own, or copy the file and give the copy to --config")
    assert _contents(here) == before  # not even a lock file made


@pytest.mark.parametrize(("first", "second"), [
    ("config_path", "kept_calibration_path"), ("config_path", "frames_path"),
    ("calibration_path", "kept_calibration_path"), ("calibration_path", "frames_path"),
    ("frames_path", "kept_calibration_path"),
])
@pytest.mark.parametrize("naming", ["the same path", "a relative path", "a symbolic link", "a hard link"])
def test_two_options_naming_one_file_by_any_name_are_refused(here: Path, first: str, second: str, naming: str) -> None:
    """``--frames X --keep-calibration X`` was refused as "another hexactl serve (process N)
    keeps the operator's frames there", N being the very service refused."""
    shared = here / "cal.toml"
    other_name = {"the same path": shared, "a relative path": Path("data/../cal.toml"),
                  "a symbolic link": here / "link.toml", "a hard link": here / "hard.toml"}[naming]
    if naming == "a symbolic link":
        other_name.symlink_to(shared)
    elif naming == "a hard link":
        os.link(shared, other_name)
    before = _contents(here)
    refusal = _refusal(_config(here / "data", **{first: shared, second: other_name}))
    options = {"config_path": "--config", "calibration_path": "--calibration", "frames_path": "--frames",
               "kept_calibration_path": "--keep-calibration"}
    assert refusal.startswith(f"{options[first]} {shared} and {options[second]} {other_name} name the same file, "), refusal
    assert "another hexactl serve" not in refusal and refusal.endswith("a file of its own" if first == "frames_path"
                                                                       else f"give the copy to {options[first]}")
    assert _contents(here) == before


def test_the_config_and_the_calibration_may_be_one_file(here: Path) -> None:
    """Both are only read: starting with the nominal geometry named twice is no clash."""
    started = Service.start(_config(here / "data", config_path=here / "cal.toml", calibration_path=here / "cal.toml",
                                    kept_calibration_path=here / "kept.toml"))
    started.close()
    assert (here / "cal.toml").read_bytes() == default_config_path().read_bytes()


def test_serve_refuses_one_file_named_twice_with_exit_2_naming_both_options(
        here: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    def start_and_stop(config: ServiceConfig) -> int:  # what run_service starts, without serving for ever
        Service.start(config).close()
        return 0

    monkeypatch.setattr(service, "run_service", start_and_stop)
    status = main(["serve", "--config", "cal.toml", "--keep-calibration", "cal.toml", "--api", LOCAL,
                   "--telemetry", LOCAL, "--data-dir", "data"])
    error = capsys.readouterr().err
    assert status == 2, error
    assert "hexactl serve: error: --config cal.toml and --keep-calibration cal.toml name the same file" in error
    assert (here / "cal.toml").read_bytes() == default_config_path().read_bytes()


# -- a kept file that is a link to nothing -------------------------------------------


@pytest.mark.parametrize("calibration_given", [False, True])
def test_a_kept_calibration_linked_to_nothing_is_refused_and_the_link_left(here: Path, calibration_given: bool) -> None:
    """``ln -s /missing/cal.toml active_calibration.toml; hexactl serve`` started on the
    nominal geometry (INFO "no calibration kept") and removed the link. With
    ``--calibration`` it is not read, but it would be replaced by a file of its own."""
    link, target = here / "active_calibration.toml", here / "unmounted" / "cal.toml"
    link.symlink_to(target)
    before = _contents(here)
    refusal = _refusal(_config(here / "data", calibration_path=here / "cal.toml" if calibration_given else None))
    assert refusal == (
        f"--keep-calibration {link}: a symbolic link to {target}, which is not there (a disk not mounted?): the "
        "calibration in force kept there can be neither restored nor kept; mount or restore the link's target, or "
        "remove the link to start with the nominal geometry")
    assert _contents(here) == before


def test_frames_linked_to_nothing_are_refused_and_the_link_left(here: Path) -> None:
    """``ln -s /missing/frames.toml frames.toml; hexactl serve`` started with no soft limits,
    said in an INFO line: a service must not run without the soft limits its operator set."""
    link, target = here / "frames.toml", here / "unmounted" / "frames.toml"
    link.unlink()
    link.symlink_to(target)
    before = _contents(here)
    refusal = _refusal(_config(here / "data"))
    assert refusal == (
        f"--frames {link}: a symbolic link to {target}, which is not there (a disk not mounted?): the operator's "
        "frames kept there can be neither restored nor kept; mount or restore the link's target, or remove the link "
        "to start with no frames and no soft limits")
    assert _contents(here) == before


def test_serve_refuses_a_link_to_nothing_with_exit_2_and_no_word_of_a_first_start(
        here: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    def start_and_stop(config: ServiceConfig) -> int:
        Service.start(config).close()
        return 0

    monkeypatch.setattr(service, "run_service", start_and_stop)
    (here / "frames.toml").unlink()
    (here / "frames.toml").symlink_to("/nonexistent-disk/frames.toml")
    status = main(["serve", "--frames", "frames.toml", "--api", LOCAL, "--telemetry", LOCAL, "--data-dir", "data"])
    error = capsys.readouterr().err
    assert status == 2, error
    assert "hexactl serve: error: --frames frames.toml: a symbolic link to /nonexistent-disk/frames.toml" in error
    assert "no such file yet" not in error
    assert (here / "frames.toml").is_symlink()


# -- a kept file that is a link to a file ----------------------------------------------


def test_kept_files_that_are_links_are_written_through_and_held_at_their_target(here: Path) -> None:
    """Found from outside: a working link (to a shared disk, say) became a file of its own
    at the first change, and its target kept the old frames; the lock lay beside the link,
    so a second service reaching the target by another link was not refused."""
    from hexactl.adapters.api.client import HexactlClient
    from hexactl.adapters.files.frames_file import load_frames

    shared = here / "shared"
    shared.mkdir()
    (here / "frames.toml").rename(shared / "frames.toml")
    (here / "frames.toml").symlink_to(shared / "frames.toml")
    (here / "other").mkdir()
    (here / "other" / "frames.toml").symlink_to(shared / "frames.toml")
    started = Service.start(_config(here / "data"))
    try:
        assert (shared / ".frames.toml.lock").exists() and not (here / ".frames.toml.lock").exists()
        refusal = _refusal(_config(here / "data", frames_path=here / "other" / "frames.toml",
                                   kept_calibration_path=here / "other" / "active_calibration.toml"))
        assert f"{shared / 'frames.toml'}: another hexactl serve" in refusal, refusal
        with HexactlClient(started.api_endpoint, timeout_s=30.0) as client:
            client.call("set_frames", tool=[0, 0, 100, 0, 0, 0])
    finally:
        started.close()
    assert (here / "frames.toml").is_symlink()
    assert load_frames(shared / "frames.toml").tool == (0, 0, 100, 0, 0, 0)


def test_a_recording_left_unfinished_is_named_at_start(here: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A service killed mid-recording leaves NAME.csv.partial, which no reader of finished
    recordings takes: the next start said nothing of it."""
    (here / "data" / "run7.csv.partial").write_text("t_s,cycle\n0.0,1\n")
    caplog.set_level("WARNING", logger="hexactl.service")
    Service.start(_config(here / "data")).close()
    said = [record.getMessage() for record in caplog.records if "run7" in record.getMessage()]
    assert said == [f"{here / 'data' / 'run7.csv.partial'}: a recording not finished (a service stopped during it, "
                    "or another's under way): its rows are kept; hexactl plot draws it; once no service writes it, "
                    "rename it to .csv or remove it"], said
