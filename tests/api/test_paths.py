"""Files named by requests: only inside the data directories, whatever the path says."""

from __future__ import annotations

import os
import socket
import threading

import pytest

from hexactl.adapters.api import paths
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
    ["../outside.toml", "sub/../../outside.toml", "{outside}", "/etc/passwd", "link.toml", "linkdir/outside.toml"],
)
def test_paths_outside_are_forbidden(service, outside, path) -> None:
    (service.data_dir / "link.toml").symlink_to(outside)
    (service.data_dir / "linkdir").symlink_to(outside.parent)
    reply = call(service, "load_calibration", path=path.format(outside=outside))
    assert reply["error"]["code"] == "forbidden_path"
    assert not service.controller.calls


def test_empty_path_is_invalid(service) -> None:
    assert call(service, "load_calibration", path="")["error"]["code"] == "invalid_request"
    assert call(service, "load_calibration", path="a\0b.toml")["error"]["code"] == "invalid_request"  # no control character
    assert not service.controller.calls


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


def read(directories: DataDirectories, text: str) -> str:
    return directories.read_text(text, ErrorCode.INVALID_CALIBRATION)[1]


def refusal(call, *arguments) -> ApiError:
    with pytest.raises(ApiError) as refused:
        call(*arguments)
    return refused.value


def test_relative_paths_try_each_directory_in_order(tmp_path) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    (second / "x.toml").write_text("second")
    directories = DataDirectories([first, second])
    assert directories.read_text("x.toml", ErrorCode.INVALID_CALIBRATION) == ((second / "x.toml").resolve(), "second")
    os.mkfifo(first / "x.toml")  # not a file: skipped, as a missing one is
    assert read(directories, "x.toml") == "second"
    (first / "x.toml").unlink()
    (first / "x.toml").write_text("first")
    assert read(directories, "x.toml") == "first"
    assert refusal(read, directories, os.path.relpath("/etc/passwd", first)).code == ErrorCode.FORBIDDEN_PATH


def test_a_link_to_outside_is_forbidden_not_missing_where_another_directory_lacks_the_name(tmp_path) -> None:
    """With several data directories (the service's default three), a link in one to a
    file outside was "no such file in the data directories", the others lacking the name:
    the operator, who sees the file there, was told it is not."""
    first, second = tmp_path / "calibrations", tmp_path / "recordings"
    first.mkdir()
    second.mkdir()
    (tmp_path / "secret.toml").write_text("outside")
    (first / "pw.toml").symlink_to(tmp_path / "secret.toml")
    refused = refusal(read, DataDirectories([second, first]), "pw.toml")
    assert refused.code == ErrorCode.FORBIDDEN_PATH and "leads outside the data directories" in refused.message
    assert str(first / "pw.toml") in refused.message and "secret" not in refused.message.replace(str(first), "")
    assert refusal(read, DataDirectories([second, first]), "none.toml").code == ErrorCode.FILE_NOT_FOUND


def test_relative_to_the_working_directory_inside_a_data_directory(tmp_path, monkeypatch) -> None:
    (tmp_path / "calibrations").mkdir()
    (tmp_path / "calibrations" / "c.toml").write_text("c")
    (tmp_path / "elsewhere.toml").write_text("")
    monkeypatch.chdir(tmp_path)
    directories = DataDirectories([tmp_path / "calibrations"])
    assert read(directories, "calibrations/c.toml") == "c"
    # only in the working directory: not found where it may be
    assert refusal(read, directories, "elsewhere.toml").code == ErrorCode.FILE_NOT_FOUND
    assert refusal(read, directories, "./elsewhere.toml/../../x").code == ErrorCode.FORBIDDEN_PATH


@pytest.fixture
def data(tmp_path):
    """A data directory with ``sub/race.toml`` in it, and ``outside/race.toml`` beside it."""
    (tmp_path / "data" / "sub").mkdir(parents=True)
    (tmp_path / "data" / "sub" / "race.toml").write_text("inside")
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "race.toml").write_text("outside")
    return tmp_path


def swapped_before(monkeypatch, name: str, swap) -> None:
    """Make ``swap()`` happen just before ``paths.<name>`` runs: after the path check."""
    original = getattr(paths, name)

    def late(*arguments, **keywords):
        swap()
        return original(*arguments, **keywords)

    monkeypatch.setattr(paths, name, late)


def replace_with_symlink(path, target) -> None:
    os.rename(path, path.with_name(path.name + ".away"))
    path.symlink_to(target)


@pytest.mark.parametrize("swapped", ["sub/race.toml", "sub"])
def test_a_symlink_swapped_in_after_the_check_is_not_followed(data, monkeypatch, swapped) -> None:
    swapped_before(monkeypatch, "_open_file_beneath",
                   lambda: replace_with_symlink(data / "data" / swapped, data / "outside" / swapped.removeprefix("sub/")))
    refused = refusal(read, DataDirectories([data / "data"]), "sub/race.toml")
    assert refused.code == ErrorCode.FILE_NOT_FOUND and "symlink swapped in" in refused.message


def test_a_fifo_swapped_in_is_refused_without_waiting_for_a_writer(data, monkeypatch) -> None:
    fifo = data / "data" / "sub" / "race.toml"
    swapped_before(monkeypatch, "_open_file_beneath", lambda: (fifo.unlink(), os.mkfifo(fifo)))
    outcome: list[BaseException | str] = []

    def attempt() -> None:
        try:
            outcome.append(read(DataDirectories([data / "data"]), "sub/race.toml"))
        except BaseException as error:  # noqa: BLE001 - handed to the test thread
            outcome.append(error)

    reader = threading.Thread(target=attempt, daemon=True)
    reader.start()
    reader.join(10.0)
    if reader.is_alive():  # blocked opening the FIFO: release it (a writer), then fail
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("reading a FIFO blocked the reader")
    [refused] = outcome
    assert isinstance(refused, ApiError) and refused.code == ErrorCode.FILE_NOT_FOUND
    assert "not a regular file (a FIFO)" in refused.message


def test_the_open_descriptor_decides_where_the_file_lies(tmp_path, monkeypatch) -> None:
    """A directory above a data directory swapped for a symlink to elsewhere after the
    check (by someone who can write there) is followed by the open; the descriptor's real
    path is what refuses the file."""
    for place in ("above", "elsewhere"):
        (tmp_path / place / "data").mkdir(parents=True)
        (tmp_path / place / "data" / "race.toml").write_text(place)
    directories = DataDirectories([tmp_path / "above" / "data"])
    swapped_before(monkeypatch, "_open_file_beneath", lambda: replace_with_symlink(tmp_path / "above", tmp_path / "elsewhere"))
    assert refusal(read, directories, "race.toml").code == ErrorCode.FORBIDDEN_PATH


def test_special_files_large_files_and_bad_paths(data) -> None:
    directories = DataDirectories([data / "data"])
    with socket.socket(socket.AF_UNIX) as listener:
        listener.bind(str(data / "data" / "socket.toml"))
        refused = refusal(read, directories, "socket.toml")
    assert refused.code == ErrorCode.FILE_NOT_FOUND and "a socket" in refused.message
    with open(data / "data" / "big.toml", "wb") as big:
        big.truncate(paths.MAX_FILE_BYTES + 1)  # sparse
    assert refusal(read, directories, "big.toml").code == ErrorCode.TOO_LARGE
    (data / "data" / "loop.toml").symlink_to("loop.toml")
    refused = refusal(read, directories, "loop.toml")
    assert refused.code == ErrorCode.FILE_NOT_FOUND and "symlink loop" in refused.message
    refused = refusal(read, directories, "sub/race.toml/x.toml")
    assert refused.code == ErrorCode.FILE_NOT_FOUND and "not a directory" in refused.message
    (data / "data" / "x.toml").write_text("a = 1\n")
    assert read(directories, "x.toml") == "a = 1\n"
    for named_as_directory in ("x.toml/", "x.toml/.", "x.toml//"):  # pathlib would drop the ending and read x.toml
        refused = refusal(read, directories, named_as_directory)
        assert refused.code == ErrorCode.FILE_NOT_FOUND and "name a file" in refused.message, named_as_directory


def test_writes_land_in_the_checked_directory(data) -> None:
    directories = DataDirectories([data / "data"])
    written = directories.write_new("sub/run.csv", b"a,b\n")
    assert written == (data / "data" / "sub" / "run.csv").resolve() and written.read_bytes() == b"a,b\n"
    assert refusal(directories.write_new, "sub/run.csv", b"").code == ErrorCode.FILE_EXISTS
    assert refusal(directories.write_new, "../outside/run.csv", b"").code == ErrorCode.FORBIDDEN_PATH
    assert refusal(directories.write_new, "none/run.csv", b"").code == ErrorCode.FILE_NOT_FOUND
    assert not (data / "outside" / "run.csv").exists()
    (data / "data" / "d.csv").mkdir()  # found from outside: "exists; a saved file is never overwritten"
    refused = refusal(directories.write_new, "d.csv", b"")
    assert refused.code == ErrorCode.FILE_EXISTS and refused.message == "d.csv: is a directory: name a file"


def test_a_directory_swapped_for_a_symlink_during_a_write_is_not_followed(data, monkeypatch) -> None:
    directories = DataDirectories([data / "data"])
    swapped_before(monkeypatch, "_open_directory_beneath", lambda: replace_with_symlink(data / "data" / "sub", data / "outside"))
    refused = refusal(directories.write_new, "sub/run.csv", b"")
    assert refused.code == ErrorCode.FILE_NOT_FOUND and "symlink swapped in" in refused.message
    monkeypatch.undo()
    (data / "data" / "sub").unlink()
    (data / "data" / "sub.away").rename(data / "data" / "sub")
    # Swapped once the directory is open: the file is written where it was checked.
    swapped_before(monkeypatch, "write_atomic", lambda: replace_with_symlink(data / "data" / "sub", data / "outside"))
    directories.write_new("sub/run.csv", b"x")
    assert (data / "data" / "sub.away" / "run.csv").read_bytes() == b"x"
    assert not (data / "outside" / "run.csv").exists()


def test_files_lists_each_directorys_regular_files_with_what_they_hold(tmp_path, nominal) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    (first / "cal.toml").write_text(geometry_to_toml(nominal))
    (first / "steps.toml").write_text('name = "steps"\n\n[[waypoint]]\npose = [0, 0, 5, 0, 0, 0]\n')
    (second / "run1.csv").write_text("t_s,cycle,lateness_us\n0.000000,1,12\n")
    (second / "plan.csv").write_text("# hexactl plan-leglock\n\nleg,x,y,z,roll,pitch,yaw,l1_setpoint\n3,0,0,0,0,0,0,1\n")
    (second / "postures.csv").write_text("posture,point,x,y,z\n1,1,0,0,0\n")  # a measurement file
    (second / "notes.txt").write_text("x")
    (second / "sub").mkdir()
    (second / "link.toml").symlink_to(first / "cal.toml")  # not followed: listed by its target's directory only
    os.mkfifo(second / "pipe.toml")  # not a regular file: not listed, never opened
    listed = DataDirectories([first, second]).files(limit=100)
    assert [(entry["name"], entry["kind"]) for entry in listed] == [
        ("cal.toml", "calibration"), ("steps.toml", "sequence"), ("notes.txt", "other"), ("plan.csv", "sequence"),
        ("postures.csv", "other"), ("run1.csv", "recording")]
    assert listed[0]["directory"] == str(first.resolve()) and listed[0]["size"] == len(geometry_to_toml(nominal))
    assert len(DataDirectories([first, second]).files(limit=2)) == 2


def test_read_chunk_reads_any_size_in_pieces_inside_the_data_directories_only(tmp_path) -> None:
    data = bytes(range(256)) * (paths.MAX_FILE_BYTES // 256 + 10)  # larger than any whole-file read
    (tmp_path / "big.csv").write_bytes(data)
    directories = DataDirectories([tmp_path])
    pieces, offset = [], 0
    while True:
        _, chunk, size = directories.read_chunk("big.csv", offset, 1 << 20)
        assert size == len(data)
        if not chunk:
            break
        pieces.append(chunk)
        offset += len(chunk)
    assert b"".join(pieces) == data
    with pytest.raises(ApiError) as refused:
        directories.read_chunk("../outside.csv", 0, 10)
    assert refused.value.code == ErrorCode.FORBIDDEN_PATH


@pytest.mark.parametrize("offset", [1000, 2**62, 2**63 - 1, 2**63, 2**64, 10**30])
def test_read_file_from_any_offset_beyond_the_end_is_the_end(service, offset) -> None:
    """Found from outside: an offset from 2**63 on was an internal_error (OverflowError),
    2**63 - 1 a file_not_found ("Invalid argument"); the schema allows any integer."""
    (service.data_dir / "small.csv").write_bytes(b"t_s\n0.0\n")
    reply = call(service, "read_file", path="small.csv", offset=offset)
    assert reply["ok"], reply
    assert (reply["data_b64"], reply["size"], reply["eof"], reply["offset"]) == ("", 8, True, offset)


def test_hidden_files_and_secret_keys_are_never_read_written_or_listed(tmp_path) -> None:
    """The configuration's directory is a data directory, everything below it too: with
    ``--config ~/platform.toml`` any loopback client or dashboard page read ``~/.ssh`` and
    the CURVE keys kept beside the configuration (an outside review)."""
    home = tmp_path / "home"
    (home / ".ssh").mkdir(parents=True)
    (home / ".ssh" / "id_ed25519").write_text("secret")
    (home / ".netrc").write_text("secret")
    (home / "keys").mkdir()
    (home / "keys" / "server.key_secret").write_text("secret")
    (home / "keys" / "server.key").write_text("public")
    (home / "cal.toml").write_text("a = 1\n")
    (home / "link.toml").symlink_to(home / ".netrc")
    directories = DataDirectories([home])
    for text in (".ssh/id_ed25519", ".netrc", "keys/server.key_secret", str(home / ".netrc"), "keys/../.netrc",
                 "link.toml"):
        for attempt in (lambda: read(directories, text), lambda: directories.read_chunk(text, 0, 100)):
            refused = refusal(attempt)
            assert refused.code == ErrorCode.FORBIDDEN_PATH and "never read or written by requests" in refused.message, text
    assert read(directories, "cal.toml") == "a = 1\n" and directories.read_chunk("keys/server.key", 0, 100)[1] == b"public"
    for text in (".bashrc", ".ssh/authorized_keys", "keys/x.key_secret"):
        assert refusal(directories.write_new, text, b"x").code == ErrorCode.FORBIDDEN_PATH, text
    assert not (home / ".bashrc").exists() and not (home / ".ssh" / "authorized_keys").exists()
    assert [entry["name"] for entry in directories.files(limit=100)] == ["cal.toml"]  # link.toml: a symlink


def test_a_name_too_long_to_write_says_to_shorten_it(data) -> None:
    """It said "File name too long; check the folder and the disk" (the security review)."""
    refused = refusal(DataDirectories([data / "data"]).write_new, "r" * 240 + ".csv", b"x")
    assert refused.code == ErrorCode.WRITE_FAILED and "give a shorter name" in refused.message, refused.message
