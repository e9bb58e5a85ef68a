"""The data recorder in simulated time: the loop's part (divisor, trigger, duration, stop,
lost rows, state) and the writer's file (columns, units, side file, measured pose)."""

from __future__ import annotations

import csv
import errno
import io
import json
import os
from pathlib import Path

import pytest

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError
from hexactl.adapters.files.recording_file import columns
from hexactl.application.recording import Recordings
from hexactl.control import recorder as recorder_module
from hexactl.control.frames import OperatorFrames
from hexactl.control.recorder import RecorderPhase, RecordingEnd
from hexactl.kinematics.axes import FramePoseMmDeg


def _rows(rig):
    return rig.controller.take_recorded()


def test_records_every_cycle_for_the_rows_asked_then_ends(rig):
    assert rig.controller.record(7, "r", 1, 10).ok
    rig.run(30)
    rows = _rows(rig)
    assert [row[0] for row in rows] == [7] * 10
    cycles = [row[1] for row in rows]
    assert cycles == list(range(cycles[0], cycles[0] + 10))
    state = rig.controller.snapshot.recorder
    assert (state.phase, state.ended, state.rows, state.lost) == (RecorderPhase.DONE, RecordingEnd.DURATION, 10, 0)


def test_divisor_records_every_nth_cycle(rig):
    assert rig.controller.record(1, "r", 4, 5).ok
    rig.run(40)
    cycles = [row[1] for row in _rows(rig)]
    assert len(cycles) == 5 and all(b - a == 4 for a, b in zip(cycles, cycles[1:]))


def test_armed_recording_starts_with_the_next_motion(rig):
    rig.enabled()
    assert rig.controller.record(2, "r", 1, 5, on_motion=True).ok
    rig.run(20)
    assert rig.controller.snapshot.recorder.phase is RecorderPhase.ARMED
    assert _rows(rig) == []
    assert rig.controller.move([1.0, 0, 0, 0, 0, 0], duration=0.5).ok
    rig.run(10)
    rows = _rows(rig)
    assert len(rows) == 5
    # the first recorded cycle is the first one moving: its commanded pose has left zero
    assert rows[0][5][0] > 0.0
    assert rig.controller.snapshot.recorder.phase is RecorderPhase.DONE


def test_a_fault_latched_while_armed_starts_the_recording(rig):
    """Found from outside: a sequence that faulted in its first cycle never showed as
    moving; the recording armed for it stayed armed, and record --stop wrote no row and
    faults_during false."""
    rig.enabled()
    assert rig.controller.record(2, "r", 1, 5, on_motion=True).ok
    rig.run(10)
    assert rig.controller.snapshot.recorder.phase is RecorderPhase.ARMED
    rig.actuators.inject_fault(2, 0x10)
    rig.run(20)
    recorder = rig.controller.snapshot.recorder
    assert recorder.phase is RecorderPhase.DONE and recorder.rows == 5 and recorder.faulted, recorder


def test_a_fault_before_an_armed_recordings_first_row_is_not_during_it(rig, recordings):
    """Found from outside: a recording armed while an E-stop was latched, run on the next
    motion after reset and enable, said faults_during (and record exited 1)."""
    assert rig.controller.estop().ok
    rig.run(3)
    recordings.start("armed", duration_s=0.1, start="next_motion")
    rig.run(20)
    recordings.poll()
    assert rig.controller.reset().ok
    rig.run_until(lambda: all(a.state.name == "DISABLED" for a in rig.controller.snapshot.feedback.actuators))
    rig.enabled()
    recordings.poll()
    assert rig.controller.move([1.0, 0, 0, 0, 0, 0], duration=0.5).ok
    assert _finish(rig, recordings)["faults_during"] is False
    recordings.start("latched", duration_s=0.1)
    assert rig.controller.estop().ok  # within it: it was
    assert _finish(rig, recordings)["faults_during"] is True

def test_stop_ends_early_and_a_second_start_is_refused_while_active(rig):
    assert rig.controller.record(3, "first", 1, 1000).ok
    rig.run(5)
    refused = rig.controller.record(4, "second", 1, 10)
    assert not refused.ok and refused.error.value == "busy" and "first" in refused.message
    assert rig.controller.record_stop().ok
    rig.run(3)
    state = rig.controller.snapshot.recorder
    assert (state.phase, state.ended) == (RecorderPhase.DONE, RecordingEnd.STOPPED)
    count = len(_rows(rig))
    rig.run(5)
    assert _rows(rig) == [] and 4 <= count <= 7
    nothing = rig.controller.record_stop()
    assert not nothing.ok and nothing.error.value == "not_recording"


def test_rows_beyond_the_cap_are_counted_lost_not_kept(rig, monkeypatch):
    monkeypatch.setattr(recorder_module, "MAX_PENDING_ROWS", 8)
    assert rig.controller.record(5, "r", 1, 20).ok
    rig.run(30)
    state = rig.controller.snapshot.recorder
    assert (state.rows, state.lost, state.phase) == (8, 12, RecorderPhase.DONE)
    assert len(_rows(rig)) == 8


def test_idle_recorder_keeps_nothing(rig):
    rig.run(20)
    assert _rows(rig) == [] and rig.controller.snapshot.recorder.phase is RecorderPhase.IDLE
    assert rig.controller.telemetry().recording is None


# -- the writer ----------------------------------------------------------------------


@pytest.fixture
def recordings(rig, tmp_path) -> Recordings:
    return Recordings(rig.controller, DataDirectories([tmp_path]))


def _finish(rig, recordings, cycles=2000):
    for _ in range(cycles):
        rig.run()
        recordings.poll()
        if recordings.state()["state"] == "done":
            return recordings.last
    raise AssertionError("the recording did not finish")


def test_writer_writes_every_cycle_with_units_and_a_side_file(rig, recordings, tmp_path):
    rig.enabled()
    reply = recordings.start("run1", duration_s=0.5)
    assert reply["rows"] == 250 and reply["rate_hz"] == 500.0
    assert (tmp_path / "run1.csv.partial").exists()
    assert rig.controller.move([2.0, 0, 1.0, 0, 0, 0.5], duration=0.1).ok
    side = _finish(rig, recordings)
    assert not (tmp_path / "run1.csv.partial").exists()
    with open(tmp_path / "run1.csv") as handle:
        table = list(csv.DictReader(handle))
    assert list(table[0]) == [name for name, _ in columns(recordings.last["signals"])]
    assert "pose_command_x_mm" in table[0] and "pose_measured_yaw_deg" in table[0] and "lateness_us" in table[0]
    cycles = [int(row["cycle"]) for row in table]
    assert len(cycles) == 250 and cycles == list(range(cycles[0], cycles[0] + 250))
    # at rest after the move, the measured pose (FK of the feedback) is the commanded one
    last = table[-1]
    for axis, tolerance in (("x_mm", 1e-3), ("z_mm", 1e-3), ("yaw_deg", 1e-4)):
        assert float(last[f"pose_measured_{axis}"]) == pytest.approx(float(last[f"pose_command_{axis}"]), abs=tolerance)
    moving = [float(row["pose_measured_x_mm"]) for row in table]
    assert moving[0] == pytest.approx(0.0, abs=1e-3) and moving == sorted(moving)
    assert float(table[-1]["pose_command_yaw_deg"]) == pytest.approx(0.5, abs=1e-6)
    written = json.loads((tmp_path / "run1.json").read_text())
    assert written == side
    assert (side["rows_written"], side["cycles_missing"], side["rows_lost"], side["ended"]) == (250, 0, 0, "duration")
    assert side["calibration_id"] == "nominal" and side["started_utc"].endswith("+00:00")
    assert {"name": "t_s", "unit": "s"} in side["columns"]


def test_a_loop_held_up_shows_in_the_side_files_longest_gap_not_in_cycles_missing(rig, recordings, tmp_path):
    # A loop held up (a 3 s stall of its process) skips the cycles' deadlines, not their
    # numbers: cycles_missing said 0, and only t_s showed the gap.
    recordings.start("steady", duration_s=0.05)
    assert _finish(rig, recordings)["longest_row_gap_s"] == pytest.approx(0.002)
    recordings.start("held", duration_s=0.1)
    rig.run(20)
    rig.clock.advance(3_000_000_000)
    side = _finish(rig, recordings)
    assert side["cycles_missing"] == 0 and side["longest_row_gap_s"] == pytest.approx(3.002)
    with open(tmp_path / "held.csv") as handle:
        times = [float(row["t_s"]) for row in csv.DictReader(handle)]
    assert max(b - a for a, b in zip(times, times[1:])) == pytest.approx(3.002)


def test_writer_in_the_work_frame_writes_the_tools_pose(rig, recordings, tmp_path):
    rig.controller.set_frames(OperatorFrames(work=FramePoseMmDeg(10.0, 0, 0, 0, 0, 0),
                                             tool=FramePoseMmDeg(0, 0, 300.0, 0, 0, 0)))
    recordings.start("w", signals=("pose_command",), frame="work", duration_s=0.01)
    side = _finish(rig, recordings)
    with open(tmp_path / "w.csv") as handle:
        row = next(csv.DictReader(handle))
    assert list(row) == ["t_s", "cycle"] + [name for name, _ in columns(("pose_command",))][2:]
    assert float(row["pose_command_x_mm"]) == pytest.approx(-10.0, abs=1e-6)
    assert float(row["pose_command_z_mm"]) == pytest.approx(300.0, abs=1e-6)
    assert side["frame"] == "work" and side["frames"]["work"][0] == 10.0


def test_writer_stop_finishes_with_stopped(rig, recordings, tmp_path):
    recordings.start("s", duration_s=10.0, start="now")
    rig.run(10)
    recordings.poll()
    assert recordings.stop()["state"] == "writing"
    side = _finish(rig, recordings)
    assert side["ended"] == "stopped" and side["cycles_missing"] == 0 and (tmp_path / "s.csv").exists()


def test_writer_refusals_name_the_problem(rig, recordings, tmp_path):
    (tmp_path / "taken.csv").write_text("x")
    with pytest.raises(ApiError, match="taken.csv exists.*choose another name") as exists:
        recordings.start("taken")
    assert exists.value.code == "file_exists"
    with pytest.raises(ApiError, match="bare file name"):
        recordings.start("../up")
    with pytest.raises(ApiError, match="unknown signals"):
        recordings.start("x", signals=("torque",))
    with pytest.raises(ApiError, match="record: signals feedback, lateness named more than once: name each signal "
                       "once") as repeated:
        recordings.start("x", signals=("lateness", "feedback", "pose_command", "feedback", "lateness"))
    assert repeated.value.details == [{"field": "signals", "problem": repeated.value.message.removeprefix("record: ")}]
    assert not (tmp_path / "x.csv.partial").exists()
    recordings.start("one", duration_s=5.0)
    with pytest.raises(ApiError, match="'one' is under way.*record_stop") as busy:
        recordings.start("two")
    assert busy.value.code == "busy" and not (tmp_path / "two.csv.partial").exists()
    with pytest.raises(ApiError, match="nothing to stop"):
        Recordings(rig.controller, DataDirectories([tmp_path])).stop()


def test_close_finishes_a_recording_under_way_as_shutdown(rig, recordings, tmp_path):
    recordings.start("c", duration_s=10.0)
    rig.run(25)
    recordings.close()
    side = json.loads(Path(tmp_path / "c.json").read_text())
    assert side["ended"] == "shutdown" and side["rows_written"] == 25 and side["cycles_missing"] == 0


class _FillingDisk(io.FileIO):
    """A file on a disk with room for ``room`` bytes: a write takes what fits, then fails ENOSPC."""

    room = 0

    def write(self, data) -> int:
        fits = self.room - self.seek(0, os.SEEK_END)
        if fits <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return super().write(bytes(data)[:fits])


def test_a_full_disk_ends_the_recording_saying_so_and_the_next_one_is_written(rig, recordings, tmp_path,
                                                                                monkeypatch):
    """A write that failed (ENOSPC) used to end the writer's thread with a traceback: the
    recording never finished (`record --wait`: "not written 30 s after it should have
    ended"), and every later one was refused busy or lost until the service restarted.
    Then the file ended in a row cut short (which `hexactl plot` refused as garbled) and
    rows_written counted the rows of the batch that failed: the side file promised rows the
    CSV did not hold."""
    with monkeypatch.context() as patched:
        patched.setattr(os, "fdopen", lambda descriptor, *arguments, **options: _FillingDisk(descriptor, "wb"))
        _FillingDisk.room = 10**6
        recordings.start("full", duration_s=10.0)
    partial = tmp_path / "full.csv.partial"
    rig.run(5)
    recordings.poll()
    _FillingDisk.room = partial.stat().st_size + 1000  # room for part of the next batch of rows
    rig.run(25)
    recordings.poll()
    side = recordings.last
    lines = partial.read_text().split("\n")
    assert lines[-1] == "", "the file ends on a whole row"
    assert len(lines) - 2 == side["rows_written"] == 5, "rows_written is what the file holds"
    assert side["ended"] == "write_failed" and side["csv"] == str(tmp_path / "full.csv.partial")
    assert side["write_error"].startswith(f"{tmp_path / 'full.csv.partial'}: No space left on device")
    assert recordings.state()["state"] == "done" and not (tmp_path / "full.csv").exists()
    rig.run()  # the stop the writer sent, carried out at the next cycle
    assert not rig.controller.snapshot.recorder.active, "the loop goes on recording for nobody"
    recordings.start("next", duration_s=0.05)
    side = _finish(rig, recordings)
    assert side["ended"] == "duration" and "write_error" not in side and (tmp_path / "next.csv").exists()


def test_a_recording_on_a_full_disk_is_refused_saying_so(recordings, tmp_path, monkeypatch):
    def full_disk(descriptor, *arguments, **options):  # /dev/full: every write fails with ENOSPC
        os.close(descriptor)
        return open("/dev/full", *arguments, **options)

    monkeypatch.setattr(os, "fdopen", full_disk)
    with pytest.raises(ApiError, match="full.csv.partial: cannot write it: No space left on device; free some space") as refused:
        recordings.start("full", duration_s=1.0)
    assert refused.value.code == "write_failed"
    assert not (tmp_path / "full.csv.partial").exists() and recordings.state()["state"] == "idle"


@pytest.mark.parametrize("tamper, problem", [
    (lambda partial: partial.unlink(), "removed while it was being written, and its rows with it"),
    (lambda partial: partial.write_text(""), "changed while it was being written ("),
])
def test_a_csv_removed_or_emptied_under_the_recorder_ends_write_failed_and_the_next_recording_is_written(
        rig, recordings, tmp_path, tamper, problem):
    """Found from outside: a .csv.partial deleted mid-recording made the finish's rename
    raise, which ended the writer's thread; every later recording was then accepted and
    lost (0 rows), until a restart. One emptied by hand was renamed NAME.csv without its
    header while its side file promised every row."""
    recordings.start("gone", duration_s=0.2)
    rig.run(20)
    recordings.poll()
    tamper(tmp_path / "gone.csv.partial")
    side = _finish(rig, recordings)
    assert side["ended"] == "write_failed", side
    assert side["write_error"].startswith(f"{tmp_path / 'gone.csv.partial'}: {problem}"), side["write_error"]
    assert "by someone else" in side["write_error"]
    assert side["csv"] == str(tmp_path / "gone.csv.partial") and not (tmp_path / "gone.csv").exists()
    assert json.loads((tmp_path / "gone.json").read_text()) == side

    recordings.start("next", duration_s=0.05)
    side = _finish(rig, recordings)
    assert side["ended"] == "duration" and "write_error" not in side, side
    assert len((tmp_path / "next.csv").read_text().splitlines()) == 1 + side["rows_written"] == 26


def test_a_csv_renamed_under_the_recorder_is_named_where_it_is_with_all_its_rows(rig, recordings, tmp_path):
    """Found from outside: a .csv.partial renamed by hand mid-recording was said to be
    "removed while the recording ended, and its rows with it", write_failed, though every
    row was in it under its new name."""
    recordings.start("moved", duration_s=0.05)
    rig.run(10)
    recordings.poll()
    (tmp_path / "moved.csv.partial").rename(tmp_path / "elsewhere.csv.partial")
    (tmp_path / "moved.csv.partial").write_text("")  # another file under its old name: not the recording
    side = _finish(rig, recordings)
    assert side["ended"] == "duration" and "write_error" not in side, side
    assert side["csv"] == str(tmp_path / "elsewhere.csv.partial") and not (tmp_path / "moved.csv").exists()
    assert len((tmp_path / "elsewhere.csv.partial").read_text().splitlines()) == 1 + side["rows_written"] == 26


def test_a_csv_that_cannot_take_its_final_name_keeps_its_partial_one_with_all_its_rows(rig, recordings, tmp_path,
                                                                                        monkeypatch):
    """A file system without hard links (EPERM) raised from the finish, as a removal did."""
    recordings.start("nolinks", duration_s=0.05)

    def no_links(*arguments, **options):
        raise PermissionError(errno.EPERM, os.strerror(errno.EPERM))

    monkeypatch.setattr(os, "link", no_links)
    side = _finish(rig, recordings)
    assert side["ended"] == "duration" and "write_error" not in side, side
    assert side["csv"] == str(tmp_path / "nolinks.csv.partial")
    assert len((tmp_path / "nolinks.csv.partial").read_text().splitlines()) == 1 + side["rows_written"] == 26


def test_an_interrupted_recordings_rows_are_not_called_a_file_to_remove(recordings, tmp_path):
    (tmp_path / "run7.csv.partial").write_text("t_s,cycle\n0.0,1\n")
    with pytest.raises(ApiError, match=r"run7.csv.partial exists; a recording never overwrites a file: the rows of a "
                       r"recording the service was stopped in .*rename it") as exists:
        recordings.start("run7")
    assert exists.value.code == "file_exists" and "remove" not in exists.value.message
