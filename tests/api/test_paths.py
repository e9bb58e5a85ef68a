"""Files named by requests: only inside the data directories, whatever the path says."""

from __future__ import annotations

import os

import pytest

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from tests.api.support import request


def call(service, cmd: str, **fields) -> dict:
    return request(service.api, {"v": 1, "id": 1, "cmd": cmd, **fields})


@pytest.fixture
def outside(service):
    """A readable calibration file next to (not inside) the data directory."""
    path = service.data_dir.parent / "outside.toml"
    path.write_text(geometry_to_toml(service.controller.geometry))
    return path


@pytest.mark.parametrize(
    "path",
    ["../outside.toml", "sub/../../outside.toml", "{outside}", "/etc/passwd", "link.toml", "linkdir/outside.toml", "a\0b.toml"],
)
def test_paths_outside_are_forbidden(service, outside, path) -> None:
    (service.data_dir / "link.toml").symlink_to(outside)
    (service.data_dir / "linkdir").symlink_to(outside.parent)
    reply = call(service, "load_calibration", path=path.format(outside=outside))
    assert reply["error"]["code"] == "forbidden_path"
    assert not service.controller.calls


def test_empty_path_is_invalid(service) -> None:
    assert call(service, "load_calibration", path="")["error"]["code"] == "invalid_request"


def test_sequence_paths_outside_are_forbidden(service, outside) -> None:
    sequence = outside.with_suffix(".seq.toml")
    sequence.write_text('name = "s"\n[[waypoint]]\npose = [0, 0, 0, 0, 0, 0]\n')
    assert call(service, "play", sequence=f"../{sequence.name}")["error"]["code"] == "forbidden_path"


def test_files_inside_are_read(service, nominal) -> None:
    (service.data_dir / "cal").mkdir()
    calibrated = nominal.model_copy(update={"name": "inside"})
    (service.data_dir / "cal" / "c.toml").write_text(geometry_to_toml(calibrated))
    (service.data_dir / "alias.toml").symlink_to(service.data_dir / "cal" / "c.toml")  # a link that stays inside
    for path in ("cal/c.toml", "cal/../cal/c.toml", str(service.data_dir / "cal" / "c.toml"), "alias.toml"):
        reply = call(service, "load_calibration", path=path)
        assert reply["ok"] and reply["calibration_id"] == geometry_id(calibrated), (path, reply)
    (service.data_dir / "s.toml").write_text('name = "mine"\n[[waypoint]]\npose = [0, 0, 5, 0, 0, 0]\ndwell = 1.0\n')
    assert call(service, "play", sequence="s.toml")["name"] == "mine"


def test_missing_and_bad_files(service) -> None:
    assert call(service, "load_calibration", path="none.toml")["error"]["code"] == "file_not_found"
    (service.data_dir / "adir.toml").mkdir()
    assert call(service, "load_calibration", path="adir.toml")["error"]["code"] == "file_not_found"
    (service.data_dir / "bad.toml").write_bytes(b"\xff\xfe")
    assert call(service, "load_calibration", path="bad.toml")["error"]["code"] == "invalid_calibration"
    (service.data_dir / "bad_seq.toml").write_text("name = 3\n")
    reply = call(service, "play", sequence="bad_seq.toml")
    assert reply["error"]["code"] == "invalid_sequence" and len(reply["error"]["details"]) >= 2


def test_relative_paths_try_each_directory_in_order(tmp_path) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    (second / "x.toml").write_text("")
    directories = DataDirectories([first, second])
    assert directories.resolve("x.toml") == (second / "x.toml").resolve()
    (first / "x.toml").write_text("")
    assert directories.resolve("x.toml") == (first / "x.toml").resolve()
    with pytest.raises(ApiError) as refused:
        directories.resolve(os.path.relpath("/etc/passwd", first))
    assert refused.value.code == ErrorCode.FORBIDDEN_PATH


def test_relative_to_the_working_directory_inside_a_data_directory(tmp_path, monkeypatch) -> None:
    (tmp_path / "calibrations").mkdir()
    (tmp_path / "calibrations" / "c.toml").write_text("")
    (tmp_path / "elsewhere.toml").write_text("")
    monkeypatch.chdir(tmp_path)
    directories = DataDirectories([tmp_path / "calibrations"])
    assert directories.resolve("calibrations/c.toml") == (tmp_path / "calibrations" / "c.toml").resolve()
    with pytest.raises(ApiError) as refused:
        directories.resolve("elsewhere.toml")  # only in the working directory: not found where it may be
    assert refused.value.code == ErrorCode.FILE_NOT_FOUND
    with pytest.raises(ApiError) as refused:
        directories.resolve("./elsewhere.toml/../../x")
    assert refused.value.code == ErrorCode.FORBIDDEN_PATH
