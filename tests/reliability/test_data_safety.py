"""Data safety. Files are written atomically: a crash in the middle of writing a
calibration, a measurement file or a recording leaves the old file whole and nothing at
the target path half-written, and the temporary a killed writer leaves is removed by a
later save once stale, never a live writer's. And no request makes the service read or write outside
its data directories, run a program or evaluate anything: checked through the API of the
real service's request handling with a Python audit hook that records every file the
process opens and every process it would start while the hostile requests are answered.
The service runs its handlers in its API process, which this process's hook cannot see,
so these tests serve the same handlers (:class:`ApiServer` and :class:`CommandHandler`,
on the service's own controller facade and data directory) from this process."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import zmq

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.commands import CommandHandler
from hexactl.adapters.api.messages import SaveRecordingRequest
from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.server import ApiServer
from hexactl.adapters.api.wire import ApiError
from hexactl.adapters.files.atomic import (
    STALE_AFTER_S,
    NotARegularFile,
    keep_aside,
    remove_stale_temporaries,
    write_atomic,
)
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml, load_geometry, save_geometry
from hexactl.adapters.files.measurements import write_measurements
from hexactl.application.service import Service
from hexactl.calibration.data import MeasurementData
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import WAIT_S, status, wait_for
from tests.reliability.support import recover, tolerating_loop_stalls

REPOSITORY = Path(__file__).resolve().parents[2]


def measurements(reading_mm: float) -> MeasurementData:
    return MeasurementData(locked_leg=np.array([0]), readings_mm=np.full((1, 6), reading_mm), lines=np.array([1]),
                           poses=np.zeros((1, 6)))


# Each kind of file: (write the old content, overwrite it with the new).
WRITERS: dict[str, Callable[[Path, Geometry], tuple[Callable[[], object], Callable[[], object]]]] = {
    "calibration": lambda path, g: (lambda: save_geometry(g.model_copy(update={"name": "old"}), path),
                                    lambda: save_geometry(g.model_copy(update={"name": "new"}), path, overwrite=True)),
    "measurements": lambda path, g: (lambda: write_measurements(path, measurements(400.0)),
                                     lambda: write_measurements(path, measurements(500.0), overwrite=True)),
    "recording": lambda path, g: (lambda: write_atomic(path, b"old\n" * 1000, overwrite=False),
                                  lambda: write_atomic(path, b"new\n" * 100_000, overwrite=True)),
}


def _fail(*args: object) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize("failing", ["os.fsync", "os.replace"])
@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, nominal, monkeypatch, kind, failing) -> None:
    target = tmp_path / f"{kind}.dat"
    write_old, write_new = WRITERS[kind](target, nominal)
    write_old()
    old = target.read_bytes()
    monkeypatch.setattr(os, failing.removeprefix("os."), _fail)
    with pytest.raises(OSError, match="No space left"):
        write_new()
    monkeypatch.undo()
    assert target.read_bytes() == old
    assert [path.name for path in tmp_path.iterdir()] == [target.name]


KILLED_WRITER = textwrap.dedent("""
    import os, sys, time
    from hexactl.adapters.files.geometry_file import load_geometry, save_geometry
    from hexactl.adapters.files.config_path import default_config_path

    def stall(descriptor):  # the new content is written, not yet synced nor renamed: die here
        print("written", flush=True)
        time.sleep(60)

    os.fsync = stall
    save_geometry(load_geometry(default_config_path()).model_copy(update={"name": "new"}), sys.argv[1], overwrite=True)
""")


def test_killed_mid_write_leaves_the_old_calibration_and_a_later_save_removes_its_temporary(tmp_path, nominal) -> None:
    """SIGKILL between write and rename: the target is the old file, whole, and the
    writer's hidden temporary (``.NAME.PID.RANDOM.tmp``) is left beside it. A save of the
    same file removes it once it is stale: kept while fresh (a writer on another host or
    in another PID namespace could still own it), removed once older than STALE_AFTER_S."""
    target = tmp_path / "cal.toml"
    save_geometry(nominal.model_copy(update={"name": "old"}), target)
    old = target.read_bytes()
    writer = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(target)], cwd=REPOSITORY,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline() == "written\n"
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
    assert target.read_bytes() == old and load_geometry(target).name == "old"
    (leftover,) = (path for path in tmp_path.iterdir() if path != target)
    assert leftover.name.startswith(f".cal.toml.{writer.pid}.") and leftover.name.endswith(".tmp")
    save_geometry(nominal.model_copy(update={"name": "next"}), target, overwrite=True)  # the next save is unharmed
    assert load_geometry(target).name == "next"
    assert leftover.exists()  # fresh: kept
    _age(leftover)
    save_geometry(nominal.model_copy(update={"name": "later"}), target, overwrite=True)
    assert load_geometry(target).name == "later"
    assert [path.name for path in tmp_path.iterdir()] == [target.name]


def _age(path: Path) -> None:
    """Make ``path`` look as a file left longer ago than a temporary stays fresh."""
    then = time.time() - STALE_AFTER_S - 60
    os.utime(path, (then, then), follow_symlinks=False)


def _dead_pid() -> int:
    """The id of a process that has ended (and been reaped)."""
    child = subprocess.Popen([sys.executable, "-c", ""])
    child.wait()
    return child.pid


def test_only_stale_temporaries_of_the_target_are_removed(tmp_path) -> None:
    target = tmp_path / "cal.toml"
    dead, alive, me = _dead_pid(), os.getppid(), os.getpid()
    stale = [f".cal.toml.{dead}.0123456789abcdef.tmp",
             f".cal.toml.{me}.fedcba9876543210.tmp"]  # this process's id, not being written: an earlier process's
    kept = [f".cal.toml.{alive}.0123456789abcdef.tmp",  # its writer still runs
            f".other.toml.{dead}.0123456789abcdef.tmp",  # another target's
            f".cal.toml.{dead}.0123456789ABCDEF.tmp", f".cal.toml.{dead}.notes.tmp", f"cal.toml.{dead}.0123456789abcdef.tmp",
            ".cal.toml.tmp", ".cal.toml.ab12cd34.tmp", ".cal.toml.0.0123456789abcdef.tmp"]  # not names write_atomic makes
    for name in stale + kept:
        (tmp_path / name).write_bytes(b"half")
        _age(tmp_path / name)
    fresh = tmp_path / f".cal.toml.{dead}.00000000000000ff.tmp"  # possibly a writer this host cannot see
    fresh.write_bytes(b"half")
    directory = tmp_path / f".cal.toml.{dead}.0000000000000001.tmp"
    directory.mkdir()
    link = tmp_path / f".cal.toml.{dead}.0000000000000002.tmp"
    link.symlink_to(tmp_path / stale[0])
    for path in (directory, link):
        _age(path)
    kept += [fresh.name, directory.name, link.name]

    write_atomic(target, b"new", overwrite=False)
    assert target.read_bytes() == b"new"
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted([target.name, *kept])


def test_a_concurrent_writers_temporary_is_never_removed(tmp_path, monkeypatch) -> None:
    """Another write of the same file runs while this one has its temporary: even aged,
    this process's own temporary in progress is not stale."""
    target = tmp_path / "cal.toml"
    sync = os.fsync
    aged: list[Path] = []
    removed: list[Path] = []

    def meanwhile(descriptor: int) -> None:  # the file's fsync, before the rename (then the folder's)
        for temporary in tmp_path.glob(".cal.toml.*.tmp"):
            _age(temporary)
            aged.append(temporary)
        removed.extend(remove_stale_temporaries(target))
        sync(descriptor)

    monkeypatch.setattr(os, "fsync", meanwhile)
    write_atomic(target, b"new", overwrite=False)
    assert len(aged) == 1 and removed == []
    assert target.read_bytes() == b"new"


@pytest.mark.parametrize("in_the_way", ["file", "symlink"])
def test_a_file_made_while_a_new_one_is_written_is_never_replaced(tmp_path, monkeypatch, in_the_way) -> None:
    """A write that must not overwrite looked for the file first and renamed over it at
    the end: a recording finished meanwhile under the name a save_recording was writing
    (or another process's save) was replaced, lost. Now the file in the way, or a
    symlink put there, refuses the write whatever came between."""
    target, outside = tmp_path / "run.csv", tmp_path / "outside.csv"
    sync = os.fsync

    def meanwhile(descriptor: int) -> None:  # the file's fsync, before it takes the name
        if not os.path.lexists(target):
            if in_the_way == "file":
                target.write_bytes(b"an hour of recording\n")
            else:
                target.symlink_to(outside)
        sync(descriptor)

    monkeypatch.setattr(os, "fsync", meanwhile)
    with pytest.raises(FileExistsError):
        write_atomic(target, b"dwell records\n", overwrite=False)
    if in_the_way == "file":
        assert target.read_bytes() == b"an hour of recording\n"
    else:
        assert target.is_symlink() and not outside.exists()
    assert list(tmp_path.glob(".run.csv.*.tmp")) == []


def test_a_new_file_is_written_where_hard_links_are_not_to_be_had(tmp_path, monkeypatch) -> None:
    """A FAT stick has no hard links: the new file takes its name by a rename there."""
    def no_links(*args: object) -> None:
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    assert write_atomic(tmp_path / "cal.toml", b"new", overwrite=False).read_bytes() == b"new"
    with pytest.raises(FileExistsError):
        write_atomic(tmp_path / "cal.toml", b"newer", overwrite=False)
    assert [path.name for path in tmp_path.iterdir()] == ["cal.toml"]



@pytest.mark.parametrize("kind", ["pipe", "socket", "folder", "link to a pipe"])
def test_overwrite_never_replaces_what_is_not_a_file(tmp_path, kind) -> None:
    """Found from outside: ``hexactl calibrate … -o /dev/null --force`` as root replaced
    the device with a file (every other process then wrote into it); a named pipe, too."""
    target = tmp_path / "cal.toml"
    if kind in ("pipe", "link to a pipe"):
        os.mkfifo(tmp_path / "pipe")
        if kind == "pipe":
            (tmp_path / "pipe").rename(target)
        else:
            target.symlink_to(tmp_path / "pipe")
    elif kind == "socket":
        import socket

        listener = socket.socket(socket.AF_UNIX)
        listener.bind(str(target))
        listener.close()
    else:
        target.mkdir()
    with pytest.raises(NotARegularFile, match="not a file: refusing to replace it"):
        write_atomic(target, b"new", overwrite=True)
    assert not (target.resolve().is_file())
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["cal.toml"] + (["pipe"] if "link" in kind else []))


def test_overwrite_through_a_symbolic_link_replaces_the_file_it_leads_to(tmp_path) -> None:
    """As the service writes a kept file that is a link (docs/cli.md): the link stays a link;
    one that leads to nothing is not written through (a disk not mounted)."""
    real, link = tmp_path / "real.toml", tmp_path / "link.toml"
    real.write_bytes(b"old")
    link.symlink_to(real)
    write_atomic(link, b"new", overwrite=True)
    assert link.is_symlink() and real.read_bytes() == b"new"
    dangling = tmp_path / "dangling.toml"
    dangling.symlink_to(tmp_path / "mnt" / "cal.toml")
    with pytest.raises(NotARegularFile, match="which is not there"):
        write_atomic(dangling, b"new", overwrite=True)
    assert dangling.is_symlink() and not (tmp_path / "mnt").exists()

@pytest.mark.parametrize("links", [True, False], ids=["hard links", "no hard links"])
def test_a_file_kept_aside_keeps_its_bytes_under_a_name_of_its_own(tmp_path, monkeypatch, links) -> None:
    """A kept file changed under the service is kept aside before it is replaced: never over
    another file kept aside, on a FAT stick too."""
    if not links:
        def no_links(*args: object) -> None:
            raise OSError(errno.EPERM, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_links)
    target = tmp_path / "frames.toml"
    write_atomic(target, b"first", overwrite=True)
    first = keep_aside(target)
    write_atomic(target, b"second", overwrite=True)  # as the service replaces what it kept aside
    second = keep_aside(target)
    write_atomic(target, b"new", overwrite=True)
    assert first != second and first.name.startswith("frames.toml.changed-")
    assert (first.read_bytes(), second.read_bytes(), target.read_bytes()) == (b"first", b"second", b"new")


def play_short(client: HexactlClient, service: Service) -> None:
    """Play a one-waypoint sequence to its end (something to record)."""

    def scenario() -> None:
        recover(client)
        client.call("play", sequence={"name": "short", "waypoints": [{"pose": [0, 0, 5, 0, 0, 0], "dwell": 0.02}]})
        wait_for(lambda: status(client)["sequence"] is None, "the sequence to end")
        assert status(client)["state"] == "enabled"

    tolerating_loop_stalls(scenario, lambda: service.controller)


def test_a_recording_whose_rename_fails_is_not_left_behind(client, service, data_dir, monkeypatch) -> None:
    play_short(client, service)
    # The service's API process writes recordings; the same handler runs here on the
    # service's own facade, so that the rename can be made to fail in this process.
    handler = CommandHandler(service.controller, DataDirectories([data_dir]))
    save = SaveRecordingRequest(v=1, id=1, cmd="save_recording", path="run.csv")
    before = sorted(path.name for path in data_dir.iterdir())
    monkeypatch.setattr(os, "replace", _fail)
    monkeypatch.setattr(os, "link", _fail)  # a new file takes its name by a link
    with pytest.raises(ApiError) as refused:
        handler(save)
    monkeypatch.undo()
    assert refused.value.code == "write_failed" and "No space left" in refused.value.message
    assert sorted(path.name for path in data_dir.iterdir()) == before
    assert handler(save)["records"] == 1  # and it is written once it can be
    assert client.call("save_recording", path="run2.csv")["records"] == 1  # so is the API process's


# -- nothing outside the data directories, nothing executed ------------------------------

_SPAWN_EVENTS = ("os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork", "subprocess.Popen", "pty.spawn",
                 "ctypes.dlopen", "webbrowser.open")
_audit: list[tuple[str, tuple]] | None = None  # events recorded while a test listens


def _hook(event: str, args: tuple) -> None:
    if _audit is not None and (event == "open" or event.startswith(_SPAWN_EVENTS)):
        _audit.append((event, args))


_hook_installed = False


@pytest.fixture
def audit() -> Iterator[list[tuple[str, tuple]]]:
    """The ``open`` and process-starting audit events of the whole process during the test
    (an audit hook cannot be removed: it is installed once and records only meanwhile)."""
    global _audit, _hook_installed
    if not _hook_installed:
        sys.addaudithook(_hook)
        _hook_installed = True
    _audit = events = []
    try:
        yield events
    finally:
        _audit = None


def opened_outside(events: list[tuple[str, tuple]], allowed: Path) -> list[str]:
    """Files opened outside ``allowed`` (descriptor opens, which carry no path, excluded;
    so are single names: the audit event does not say the directory descriptor they are
    opened from, one step at a time beneath a data directory by hexactl.adapters.api.paths)."""
    paths = [args[0] for event, args in events if event == "open" and isinstance(args[0], (str, bytes, os.PathLike))
             and os.sep in os.fsdecode(args[0])]
    return [str(path) for path in paths if not Path(os.fsdecode(path)).resolve().is_relative_to(allowed.resolve())]


@pytest.fixture
def outside(data_dir: Path, nominal: Geometry) -> Path:
    """Beside the data directory: a valid calibration (were it read, it would be accepted)
    and links to it from inside; inside, a FIFO (reading it would block the API thread)."""
    directory = data_dir.parent / "outside"
    directory.mkdir(exist_ok=True)
    canary = directory / "canary.toml"
    canary.write_text(geometry_to_toml(nominal.model_copy(update={"name": "canary"})))
    for link, points_to in (("link_out.toml", canary), ("linkdir", directory)):
        if not (data_dir / link).is_symlink():
            (data_dir / link).symlink_to(points_to)
    if not (data_dir / "fifo.toml").exists():
        os.mkfifo(data_dir / "fifo.toml")
    return directory


def hostile_reads(outside: Path) -> list[str]:
    return ["../outside/canary.toml", "link_out.toml", "linkdir/canary.toml", str(outside / "canary.toml"),
            "/etc/passwd", "/etc/shadow", "/proc/self/environ", "/dev/zero", "fifo.toml", "~/canary.toml",
            "$HOME/canary.toml", "file:///etc/passwd", "%2e%2e/outside/canary.toml", "sub/../../outside/canary.toml"]


@pytest.fixture
def client_here(service: Service, data_dir: Path) -> Iterator[HexactlClient]:
    """A client of the service's request handling served from this process."""
    context = zmq.Context()
    server = ApiServer(context, "tcp://127.0.0.1:*", CommandHandler(service.controller, DataDirectories([data_dir])))
    server.start()
    try:
        with HexactlClient(server.endpoint, timeout_s=WAIT_S) as client:
            yield client
    finally:
        server.close()
        context.term()


def test_no_request_reads_outside_the_data_directory(client_here, data_dir, outside, audit) -> None:
    client = client_here
    before = status(client)["calibration_id"]
    for path in hostile_reads(outside):
        for cmd, fields in (("load_calibration", {"path": path}), ("play", {"sequence": path.removesuffix(".toml") + ".toml"})):
            reply = client.request(cmd, **fields)
            assert reply["ok"] is False and reply["error"]["code"] in ("forbidden_path", "file_not_found"), (path, reply)
    assert status(client)["calibration_id"] == before
    assert opened_outside(audit, data_dir) == []
    assert not [event for event, _ in audit if event != "open"]
    (data_dir / "inside.toml").write_text("not a calibration")
    audit.clear()  # the hook does see the files the handlers read inside
    assert client.request("load_calibration", path="inside.toml")["error"]["code"] == "invalid_calibration"
    assert "inside.toml" in [os.fsdecode(args[0]) for event, args in audit if event == "open"]


def test_no_request_writes_outside_the_data_directory(client_here, service, data_dir, outside, audit) -> None:
    client = client_here
    play_short(client, service)
    for path in ("../outside/escaped.csv", "linkdir/escaped.csv", str(outside / "escaped.csv"), "../escaped.csv",
                 "/tmp/escaped.csv", "link_out.toml", "linkdir", "..", "missing/escaped.csv"):
        reply = client.request("save_recording", path=path)
        assert reply["ok"] is False and reply["error"]["code"] in ("forbidden_path", "file_not_found", "file_exists",
                                                                   "invalid_request"), (path, reply)
    assert [path.name for path in outside.iterdir()] == ["canary.toml"]
    assert not (data_dir.parent / "escaped.csv").exists() and not Path("/tmp/escaped.csv").exists()
    assert opened_outside(audit, data_dir) == []


def test_calibration_text_is_data_never_code(client_here, data_dir, nominal, audit, tmp_path) -> None:
    """TOML has no includes, no references and no code; the service treats every string as
    data: a name asking a shell for something stays a name, and keys the format does not
    know are refused."""
    client = client_here
    flag = tmp_path / "ran"
    payload = f"$(touch {flag}) `touch {flag}` __import__('os').system('touch {flag}')"
    named = nominal.model_copy(update={"name": payload})
    texts = {
        "unknown keys": geometry_to_toml(nominal) + f'\ninclude = "/etc/passwd"\n[python]\ncode = "{payload}"\n',
        "nested": "x = " + "[" * 1000 + "]" * 1000,
        "not UTF-8 text": "\udcff",
    }
    for name, text in texts.items():
        reply = client.request("load_calibration", toml=text)
        assert reply["ok"] is False and reply["error"]["code"] in ("invalid_calibration", "invalid_request"), (name, reply)
    reply = client.call("load_calibration", toml=geometry_to_toml(named))  # at rest: a no-op swap, named oddly
    assert reply["calibration_id"] == geometry_id(named)
    client.call("rollback_calibration")
    assert not flag.exists()
    assert not [event for event, _ in audit if event != "open"]
    assert opened_outside(audit, data_dir) == []
