"""Files an operator hands the command line, as an outside tester found them: a file saved
by a Windows editor (a UTF-8 byte-order mark) was refused as "not valid TOML: Invalid
statement (at line 1, column 1)" though its first line looked right, and one saved as
UTF-16 was "'utf-8' codec can't decode byte 0xff in position 0"; a full disk under an
output said "[Errno 28] No space left on device" naming no file, and under `calibrate
--report` ended in a traceback with the status of an untrustworthy calibration (1)."""

from __future__ import annotations

import codecs
import errno
import os
from pathlib import Path

import pytest

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError, ErrorCode
from hexactl.adapters.cli.common import write_failed
from hexactl.adapters.files.text import TextFileError, decode_text
from tests.cli.test_cli_robustness import exits_with

ROOT = Path(__file__).resolve().parents[2]
NOMINAL = (ROOT / "config" / "platform.toml").read_text(encoding="utf-8")
SAVE_AS = "save it as UTF-8"


def saved(path: Path, text: str, encoding: str) -> Path:
    """``text`` saved at ``path`` as a Windows program saves it in ``encoding``."""
    if encoding == "utf-8 with BOM":
        path.write_bytes(codecs.BOM_UTF8 + text.encode("utf-8"))
    elif encoding == "utf-8 CRLF":
        path.write_bytes(text.replace("\n", "\r\n").encode("utf-8"))
    else:
        path.write_bytes(text.encode(encoding))
    return path


@pytest.mark.parametrize("encoding", ["utf-8 with BOM", "utf-8 CRLF"])
def test_a_geometry_saved_with_a_byte_order_mark_or_crlf_is_read(encoding, tmp_path, capsys) -> None:
    config = saved(tmp_path / "platform.toml", NOMINAL, encoding)
    assert exits_with(["ik", "0", "0", "0", "0", "0", "0", "--config", str(config)]) == 0
    assert "359.976" in capsys.readouterr().out


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-32", "cp1252"])
@pytest.mark.parametrize("argv", [
    ["ik", "0", "0", "0", "0", "0", "0", "--config", "{file}"],
    ["load-calibration", "{file}", "--api", "ipc://{tmp}/nobody", "--timeout", "0.2"],
    ["calibrate", "{file}", "-o", "{tmp}/cal.toml"],
    ["plot", "{file}"],
], ids=lambda argv: argv[0])
def test_a_file_not_in_utf_8_is_refused_naming_it_and_how_to_save_it(argv, encoding, tmp_path, capsys) -> None:
    """Before anything is sent or computed: exit 2, the file named and what to do."""
    text = NOMINAL if argv[0] in ("ik", "load-calibration") else "t_s,cycle,l1\n0.0,1,350.0\n"
    wrong = saved(tmp_path / "file", text + "# 20 °C\n", encoding)
    assert exits_with([word.format(file=wrong, tmp=tmp_path) for word in argv]) == 2
    err = capsys.readouterr().err
    assert f"error: {wrong}: " in err and ("UTF-16" in err or "not UTF-8 text (byte 0x" in err), err
    assert SAVE_AS in err and "Traceback" not in err and "codec" not in err


@pytest.mark.parametrize("argv", [
    ["ik", "0", "0", "0", "0", "0", "0", "--config", "{file}"],
    ["calibrate", "{file}", "-o", "{tmp}/cal.toml"],
    ["plot", "{file}"],
    ["cue", "{file}", "--plan-only"],
], ids=lambda argv: argv[0])
@pytest.mark.parametrize(("name", "said"), [
    ("", "a folder, not a file: name a file in it"),
    ("missing.csv", "no such file"),  # plot and cue then say where theirs are
])
def test_a_folder_or_a_missing_file_is_named_as_such(argv, name, said, tmp_path, capsys) -> None:
    """Found from outside: a folder read "cannot read: [Errno 21] Is a directory: '/tmp'"."""
    path = tmp_path / name if name else tmp_path
    assert exits_with([word.format(file=path, tmp=tmp_path) for word in argv]) == 2
    err = capsys.readouterr().err
    assert f"{path}: {said}" in err and "Errno" not in err, err


def test_a_missing_file_named_relatively_says_where_it_was_looked_for(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert exits_with(["calibrate", "missing.csv", "-o", "cal.toml"]) == 2
    assert f"missing.csv: no such file: check the name (a relative name is looked up in {tmp_path})" in \
        capsys.readouterr().err


def test_the_client_file_with_a_byte_order_mark_is_read(tmp_path, monkeypatch, capsys) -> None:
    client = saved(tmp_path / "client.toml", f'api = "ipc://{tmp_path}/nobody"\n', "utf-8 with BOM")
    monkeypatch.setenv("HEXACTL_CLIENT_CONFIG", str(client))
    monkeypatch.delenv("HEXACTL_API", raising=False)
    assert exits_with(["status", "--timeout", "0.2"]) == 2
    assert f"no answer from ipc://{tmp_path}/nobody" in capsys.readouterr().err


@pytest.mark.parametrize("encoding", ["utf-8 with BOM", "utf-16"])
def test_the_service_reads_a_sequence_with_a_byte_order_mark_and_names_one_in_utf_16(encoding, tmp_path) -> None:
    saved(tmp_path / "lift.toml", 'name = "lift"\n[[waypoint]]\npose = [0, 0, 5, 0, 0, 0]\n', encoding)
    directories = DataDirectories([tmp_path])
    if encoding == "utf-16":
        with pytest.raises(ApiError, match=f"lift.toml: UTF-16 or UTF-32 text .*{SAVE_AS}"):
            directories.read_text("lift.toml", ErrorCode.INVALID_SEQUENCE)
    else:
        assert directories.read_text("lift.toml", ErrorCode.INVALID_SEQUENCE)[1].startswith('name = "lift"')


def test_a_nul_byte_is_named_with_its_line() -> None:
    with pytest.raises(TextFileError, match=r"^f.csv: a NUL byte on line 2 .* not UTF-8 text"):
        decode_text(b"a,b\n1,\0\n", "f.csv")


# -- writing on a full disk ---------------------------------------------------------------


def no_space(*arguments: object, **options: object) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file written fails as on a full disk (where an atomic write finds out: its fsync)."""
    monkeypatch.setattr(os, "fsync", no_space)


@pytest.mark.usefixtures("full_disk")
def test_a_full_disk_under_an_output_names_the_file_and_what_to_do(tmp_path, capsys) -> None:
    plan = tmp_path / "plan.csv"
    assert exits_with(["plan-leglock", "--leg", "1", "--count", "8", "--candidates", "200", "-o", str(plan)]) == 2
    err = capsys.readouterr().err
    assert f"cannot write {plan}: No space left on device; free some space there, or choose another place" in err
    assert not plan.exists() and list(tmp_path.iterdir()) == []


def test_a_full_disk_under_the_report_is_bad_input_not_a_traceback(tmp_path, monkeypatch, capsys) -> None:
    """The calibration is written; the report is not: exit 2 naming the report's folder."""
    data = tmp_path / "data.csv"
    assert exits_with(["simulate-campaign", "-o", str(data), "--per-leg", "4"]) == 0
    from hexactl.adapters.report import html

    monkeypatch.setattr(html, "write_report", no_space)
    report = tmp_path / "report"
    argv = ["calibrate", str(data), "-o", str(tmp_path / "cal.toml"), "--report", str(report)]
    assert exits_with(argv) == 2
    captured = capsys.readouterr()
    assert f"wrote {tmp_path / 'cal.toml'}" in captured.out
    assert f"error: cannot write {report}: No space left on device; free some space there" in captured.err


def test_a_refusal_of_hexactl_s_own_is_passed_on_as_it_says_what_to_do() -> None:
    refusal = FileExistsError("plan.csv exists; refusing to overwrite it (use --force)")
    assert str(write_failed("plan.csv", refusal)) == str(refusal)


def test_a_write_refused_for_permission_says_to_write_where_one_may() -> None:
    denied = PermissionError(errno.EACCES, "Permission denied")
    assert str(write_failed("/etc/plan.csv", denied)) == ("cannot write /etc/plan.csv: Permission denied; write where "
                                                          "you have permission (and the file system is not "
                                                          "read-only), or choose another place")
