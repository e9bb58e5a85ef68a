"""Files an operator hands the command line, as an outside tester found them: a file saved
by a Windows editor (a UTF-8 byte-order mark) was refused as "not valid TOML: Invalid
statement (at line 1, column 1)" though its first line looked right, and one saved as
UTF-16 was "'utf-8' codec can't decode byte 0xff in position 0"."""

from __future__ import annotations

import codecs
from pathlib import Path

import pytest

from hexactl.adapters.api.paths import DataDirectories
from hexactl.adapters.api.wire import ApiError, ErrorCode
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
