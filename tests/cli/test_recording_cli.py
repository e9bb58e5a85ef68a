"""``hexactl record`` against a running service and ``hexactl plot`` of what it wrote."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexactl.adapters.cli.main import main
from hexactl.application.service import Service


@pytest.fixture(scope="module")
def api(running: Service) -> str:
    return running.api_endpoint


def test_record_wait_writes_the_file_and_plot_draws_it(api, data_dir, tmp_path, capsys) -> None:
    assert main(["record", "cli1", "--duration", "0.3", "--wait", "--api", api]) == 0
    out = capsys.readouterr().out
    csv_path = data_dir / "cli1.csv"
    assert f"{csv_path}: 150 rows, ended: duration" in out
    side = json.loads((data_dir / "cli1.json").read_text())
    assert side["rows_written"] == 150 and side["cycles_missing"] == 0

    image = tmp_path / "cli1.png"
    assert main(["plot", str(csv_path), "-o", str(image)]) == 0
    assert image.stat().st_size > 20_000  # six panels of lines, not an empty canvas
    import matplotlib.image

    pixels = matplotlib.image.imread(image)
    assert pixels.shape[0] > 1000 and pixels.shape[1] == 1000  # six panels, 10 in at 100 dpi


def test_record_refusals_exit_1_and_say_why(api, data_dir, capsys) -> None:
    (data_dir / "taken.csv").write_text("x")
    assert main(["record", "taken", "--duration", "1", "--api", api]) == 1
    assert "taken.csv exists" in capsys.readouterr().err
    assert main(["record", "--stop", "--api", api]) == 1
    assert "nothing to stop" in capsys.readouterr().err
    assert main(["record", "--api", api]) == 2
    assert "give NAME and --duration" in capsys.readouterr().err


def test_record_stop_ends_a_recording_early(api, data_dir, capsys) -> None:
    assert main(["record", "early", "--duration", "600", "--signals", "lateness,compute", "--api", api]) == 0
    assert main(["record", "--stop", "--api", api]) == 0
    assert "early.csv" in capsys.readouterr().out and (data_dir / "early.json").exists()
    assert json.loads((data_dir / "early.json").read_text())["ended"] == "stopped"


def test_record_wait_reports_the_side_file_when_the_service_stops_answering(api, data_dir, monkeypatch,
                                                                          capsys) -> None:
    """A service stopped by a signal ends the recording and writes its files, then answers
    no more: --wait said only "no answer" (exit 2) of a recording whose file was written."""
    from hexactl.adapters.api.client import ServiceUnavailable
    from hexactl.adapters.cli import recording_commands

    def service_stops(client, name, reply, on_motion):  # as SIGTERM: the recording ends, the service goes
        client.request("record_stop")
        raise ServiceUnavailable(f"no answer from {api} within 5 s: is `hexactl serve` running there?")

    monkeypatch.setattr(recording_commands, "_wait_written", service_stops)
    # Stopped, cut short: 1, as move --wait is when a stop ends the move (found from outside:
    # record --on-motion --wait && analyse went on with an empty file)
    assert main(["record", "gone", "--duration", "600", "--wait", "--api", api]) == 1
    captured = capsys.readouterr()
    assert f"{data_dir / 'gone.csv'}: " in captured.out and "ended: stopped" in captured.out
    assert "hexactl record: it was stopped after " in captured.err and " of its 300000 rows (record --stop, or " \
           "the service stopping)" in captured.err
    assert f"the service stopped answering (no answer from {api}" in captured.err
    assert f"its side file {data_dir / 'gone.json'} says how the recording ended" in captured.err

    def side_file_elsewhere(client, name, reply, on_motion):  # a service on another machine
        client.request("record_stop")
        (data_dir / "far.json").unlink()
        raise ServiceUnavailable("no answer")

    monkeypatch.setattr(recording_commands, "_wait_written", side_file_elsewhere)
    assert main(["record", "far", "--duration", "600", "--wait", "--api", api]) == 2
    assert (f"how it ended is in far.json beside {data_dir / 'far.csv'} on the service's machine"
            in capsys.readouterr().err)


@pytest.mark.parametrize(("text", "said"), [
    (None, "no such file"),
    ("t_s,cycle,lateness_us\n0.0,1,5.0\n0.002,2\n", "line 3 has 2 values for 3 columns"),
    ("a,b\n1,2\n", "not a recording (its header has no t_s and no cycle column)"),
    # Found from outside: a dwell record (save-recording) and an empty file were both said to
    # have no t_s and cycle columns
    ("t_s,command_x\n1.0,2.0\n", "not a recording (its header has no cycle column)"),
    ("", "plot.csv: empty: plot a file made by hexactl record"),
], ids=["missing", "garbled", "other", "dwell-record", "empty"])
def test_plot_refuses_missing_and_garbled_files(text, said, tmp_path, capsys) -> None:
    path = tmp_path / "plot.csv"
    if text is not None:
        path.write_text(text)
    assert main(["plot", str(path)]) == 2
    assert said in capsys.readouterr().err


def test_plot_writes_where_it_says_and_never_over_its_input(tmp_path, capsys) -> None:
    recording = tmp_path / "r1.csv"
    written = "t_s,cycle,lateness_us\n0.0,1,5.0\n0.002,2,7.0\n"
    recording.write_text(written)
    for out in (recording, tmp_path / "r1.CSV", tmp_path / "r1.json", tmp_path / "r1"):
        assert main(["plot", str(recording), "-o", str(out)]) == 2  # refused, not a traceback
        error = capsys.readouterr().err
        assert str(out) in error and ("input" in error or ".png, .svg, .pdf" in error), error
    assert recording.read_text() == written and sorted(p.name for p in tmp_path.iterdir()) == ["r1.csv"]
    (tmp_path / "folder.png").mkdir()
    assert main(["plot", str(recording), "-o", str(tmp_path / "folder.png")]) == 2
    assert "is a folder" in capsys.readouterr().err
    image = tmp_path / "new" / "deeper" / "r1.svg"
    assert main(["plot", str(recording), "-o", str(image)]) == 0  # missing folders are made
    assert capsys.readouterr().out.strip() == str(image) and image.read_text().startswith("<?xml")


def test_record_wait_exits_1_when_a_fault_came_during_the_recording(capsys) -> None:
    from hexactl.adapters.cli.recording_commands import _report_written

    side = {"csv": "/data/run.csv", "rows_written": 150, "ended": "duration", "cycles_missing": 0}
    assert _report_written(side, as_json=False, waited=True) == 0
    assert _report_written({**side, "faults_during": True}, as_json=False, waited=True) == 1
    captured = capsys.readouterr()
    assert "/data/run.csv: 150 rows, ended: duration" in captured.out
    assert captured.err == ("hexactl record: the controller was in FAULT or ESTOP during it: the motion recorded is "
                            "not the one planned (the service's log says when)\n")


def test_record_wait_notes_a_loop_held_up_during_the_recording(capsys) -> None:
    from hexactl.adapters.cli.recording_commands import _report_written

    side = {"csv": "/data/run.csv", "rows_written": 150, "ended": "duration", "cycles_missing": 0, "rate_hz": 10.0,
            "longest_row_gap_s": 0.149}
    assert _report_written(side, as_json=False, waited=True) == 0 and "note" not in capsys.readouterr().out
    assert _report_written({**side, "longest_row_gap_s": 3.1}, as_json=False, waited=True) == 0  # the data are there
    assert capsys.readouterr().out.splitlines()[-1] == ("note: rows up to 3.100 s apart, every 0.1 s planned: the "
                                                        "control loop was held up (its cycles numbered on, late); t_s "
                                                        "has each row's time")


def test_record_wait_says_why_a_recording_could_not_be_written(capsys) -> None:
    from hexactl.adapters.cli.recording_commands import _report_written

    error = "/data/run.csv.partial: No space left on device: the rows after those in it are not recorded; free some space"
    side = {"csv": "/data/run.csv.partial", "rows_written": 40, "ended": "write_failed", "write_error": error}
    assert _report_written(side, as_json=False, waited=True) == 1
    assert capsys.readouterr().err == f"hexactl record: it could not be written whole: {error}\n"


@settings(max_examples=200, deadline=None)
@given(values=st.lists(st.one_of(st.floats(-1e6, 1e6), st.just(float("nan"))), min_size=1, max_size=400),
       buckets=st.integers(1, 50))
def test_a_long_line_is_drawn_as_its_envelope_keeping_every_extreme(values, buckets) -> None:
    from hexactl.adapters.cli.recording_commands import envelope

    data = np.array(values)
    time_s = np.arange(len(data)) * 0.002
    t, drawn = envelope(time_s, data, buckets)
    assert len(drawn) == len(t) <= max(2 * buckets, len(data))
    assert np.all(np.diff(t) >= 0)  # in time order
    finite = data[np.isfinite(data)]
    if finite.size:  # the highest spike and the deepest dip stay in the image
        assert np.nanmax(drawn) == finite.max() and np.nanmin(drawn) == finite.min()
    else:
        assert np.all(np.isnan(drawn))


def test_plot_reads_a_long_recording_into_arrays_with_gaps_for_empty_cells(tmp_path, capsys) -> None:
    from hexactl.adapters.cli.recording_commands import PLOT_BUCKETS
    from hexactl.adapters.files.recording_file import read_recording

    rows = 3 * PLOT_BUCKETS
    lines = ["t_s,cycle,pose_measured_x_mm,lateness_us"]
    lines += [f"{n * 0.002:.3f},{n},{'' if n < 5 else n % 7},{9999 if n == 4321 else 5}" for n in range(rows)]
    recording = tmp_path / "long.csv"
    recording.write_text("\ufeff" + "\n".join(lines) + "\n")  # a byte-order mark is dropped
    header, columns, cut_line = read_recording(recording)
    assert cut_line is None
    assert header == ["t_s", "cycle", "pose_measured_x_mm", "lateness_us"]
    assert all(column.dtype == np.float64 and len(column) == rows for column in columns)
    assert np.isnan(columns[2][:5]).all() and columns[2][5] == 5 and columns[3].max() == 9999
    assert main(["plot", str(recording)]) == 0 and capsys.readouterr().out.strip() == str(tmp_path / "long.png")
    (tmp_path / "wide.csv").write_bytes("t_s,cycle\n0,1\n".encode("utf-16"))
    assert main(["plot", str(tmp_path / "wide.csv")]) == 2
    assert "UTF-16 or UTF-32 text (it starts with that byte-order mark), not UTF-8" in capsys.readouterr().err
    (tmp_path / "latin.csv").write_bytes(b"t_s,cycle,note\n0,1,2\n0.002,2,\xe9\n")
    assert main(["plot", str(tmp_path / "latin.csv")]) == 2
    assert "not UTF-8 text" in capsys.readouterr().err


def test_plot_leaves_out_a_last_line_an_interruption_cut(tmp_path, capsys) -> None:
    """An interrupted recording's last line may be cut, even within a number (12.5 of
    12.345): it was refused as garbled, or read as a number it never was."""
    partial = tmp_path / "run.csv.partial"
    partial.write_text("t_s,cycle,lateness_us\n0.0,1,5.0\n0.002,2,7.0\n0.004,3,12.3")
    image = tmp_path / "run.png"
    assert main(["plot", str(partial), "-o", str(image)]) == 0 and image.exists()
    assert f"{partial}: line 4 was cut (an interrupted recording?): left out" in capsys.readouterr().err
    from hexactl.adapters.files.recording_file import read_recording

    partial.write_text("t_s,cycle,lateness_us\n0.0,1,5.0\n0.002,2")  # cut within its second value
    _, columns, cut_line = read_recording(partial)
    assert [list(column) for column in columns] == [[0.0], [1.0], [5.0]] and cut_line == 3
    whole = tmp_path / "whole.csv"
    whole.write_text("t_s,cycle,lateness_us\n0.0,1,5.0\n0.002,2\n0.004,3,1\n")  # a short line within: garbled
    assert main(["plot", str(whole)]) == 2
    assert "line 3 has 2 values for 3 columns: the file is garbled" in capsys.readouterr().err
