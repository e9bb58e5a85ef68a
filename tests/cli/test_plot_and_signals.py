"""``hexactl plot`` titles the image from the recording's side file; ``hexactl record
--signals ''`` is refused naming the option, not sent as "all signals"."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hexactl.adapters.cli import recording_commands
from hexactl.adapters.cli.main import main

RECORDING = ("t_s,cycle,pose_command_x_mm,pose_command_roll_deg,lateness_us\n"
             "0.0,1,0.0,0.0,5.0\n0.002,2,0.1,0.01,7.0\n")
"""Two units in one panel (mm left, degrees on a second axis), one in another."""


def test_plot_titles_the_image_from_the_side_file_beside_the_recording(tmp_path: Path, monkeypatch, capsys) -> None:
    """The loop over a panel's units reused the name holding the side file: the title was
    the file's stem whatever the side file said."""
    import matplotlib

    monkeypatch.setitem(matplotlib.rcParams, "svg.fonttype", "none")  # the title as text, not as paths
    recording = tmp_path / "term2.csv"
    recording.write_text(RECORDING)
    (tmp_path / "term2.json").write_text(json.dumps({
        "name": "term2", "rate_hz": 500, "frame": "work", "started_utc": "2024-05-01T10:00:00Z",
        "rows_written": 2, "ended": "duration"}))
    image = tmp_path / "term2.svg"
    assert main(["plot", str(recording), "-o", str(image)]) == 0, capsys.readouterr().err
    assert "term2: 500 Hz, frame work, from 2024-05-01T10:00:00Z, 2 rows, ended duration" in image.read_text()


@pytest.mark.parametrize("signals", ["", ",", " , "])
def test_record_refuses_an_empty_signal_list_naming_the_option(signals: str, monkeypatch, capsys) -> None:
    """The empty list was dropped from the request, and every signal recorded."""
    def connect(*arguments: object, **options: object) -> None:
        pytest.fail("the request was to be sent")

    monkeypatch.setattr(recording_commands, "connect", connect)
    with pytest.raises(SystemExit) as exit:
        main(["record", "run1", "--duration", "1", "--signals", signals])
    assert exit.value.code == 2
    error = capsys.readouterr().err
    assert ("argument --signals: name at least one signal (leave --signals out to record all): choose among "
            "pose_command,pose_measured,setpoints,feedback,lateness,compute") in error, error


def test_record_refuses_a_signal_named_twice_before_sending(monkeypatch, capsys) -> None:
    """Found from outside: the service refused it (exit 1) where every other bad --signals exits 2."""
    def connect(*arguments: object, **options: object) -> None:
        pytest.fail("the request was to be sent")

    monkeypatch.setattr(recording_commands, "connect", connect)
    with pytest.raises(SystemExit) as exit:
        main(["record", "run1", "--duration", "1", "--signals", "lateness,pose_command,lateness"])
    assert exit.value.code == 2
    assert "argument --signals: lateness named more than once: name each signal once" in capsys.readouterr().err


def test_plot_leaves_out_a_side_file_of_other_columns_and_says_when_time_goes_back(tmp_path: Path, monkeypatch,
                                                                                      capsys) -> None:
    """Found from outside: another recording's side file titled the image (its name, rate
    and rows), and a t_s that went back was plotted without a word."""
    import matplotlib

    monkeypatch.setitem(matplotlib.rcParams, "svg.fonttype", "none")  # the title as text
    recording = tmp_path / "mine.csv"
    recording.write_text(RECORDING.replace("0.002,2,", "-0.002,2,"))
    (tmp_path / "mine.json").write_text(json.dumps({
        "name": "other", "rate_hz": 250, "frame": "zero", "rows_written": 1000, "ended": "duration",
        "columns": [{"name": "t_s", "unit": "s"}, {"name": "cycle", "unit": ""}, {"name": "lateness_us", "unit": "us"}]}))
    image = tmp_path / "mine.svg"
    assert main(["plot", str(recording), "-o", str(image)]) == 0
    err = capsys.readouterr().err
    assert f"{tmp_path / 'mine.json'} describes other columns (another recording's?): plotted without it" in err, err
    assert "t_s goes back at row 2 of its values" in err, err
    assert "other: 250" not in image.read_text()
