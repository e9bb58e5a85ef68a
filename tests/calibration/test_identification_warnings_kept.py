"""A calibration file keeps its identification's status and warnings.

Found from outside: eight postures gave a file whose worst combination was known to
±70 mm, written "weakly determined" with exit 0; the status and the warnings were printed
once, not kept in the file, and the controller then loaded it without a word. The file now
keeps them, ``load-calibration`` repeats them (the controller's side:
``tests/control/test_calibration_swap.py``) and the service logs them at start.
"""

from __future__ import annotations

from hexactl.adapters.cli.service_commands import format_ok_reply
from hexactl.adapters.files.geometry_file import geometry_to_toml, parse_geometry
from hexactl.calibration.identification import calibration_geometry, calibration_info, identify
from hexactl.calibration.results import IdentificationOptions, IdentificationStatus


def test_a_weakly_determined_calibration_keeps_its_status_and_warnings_through_its_file(nominal, leglock_campaign):
    strict = IdentificationOptions(max_predicted_position_mm=1e-6)  # every fit of these data is then weakly determined
    result = identify(leglock_campaign.data, nominal, strict)
    assert result.status is IdentificationStatus.WEAKLY_DETERMINED
    assert any(warning.startswith("weakly determined: the parameter uncertainty alone") for warning in result.warnings)
    info = calibration_info(result, "2026-01-01T00:00:00+00:00", "0" * 64, nominal.name)
    text = geometry_to_toml(calibration_geometry(nominal, result, info))
    assert 'status = "weakly determined"' in text
    read = parse_geometry(text, "cal.toml")
    assert read.calibration.status == "weakly determined"
    assert read.identification_warnings == list(result.warnings)


def test_an_ok_calibration_says_ok_and_one_written_before_reads_as_without_warnings(nominal, leglock_campaign):
    result = identify(leglock_campaign.data, nominal)
    assert result.status is IdentificationStatus.OK
    info = calibration_info(result, "2026-01-01T00:00:00+00:00", "0" * 64, nominal.name)
    calibrated = calibration_geometry(nominal, result, info)
    assert parse_geometry(geometry_to_toml(calibrated), "cal.toml").calibration.status == "ok"
    document = calibrated.model_dump(mode="json", exclude_none=True)
    for key in ("status", "warnings"):  # as earlier versions wrote it
        del document["calibration"][key]
    older = parse_geometry(geometry_to_toml(type(calibrated).model_validate(document)), "old.toml")
    assert older.calibration.status is None and older.identification_warnings == []
    assert nominal.identification_warnings == []  # a geometry file


def test_load_calibration_prints_each_warning_on_a_line_of_its_own() -> None:
    reply = {"ok": True, "message": "calibration abc loaded", "calibration_id": "abc", "change_mm": 0.0,
             "warnings": ["weakly determined: … ±70.6 mm: add or spread postures", "the base moved as a whole"]}
    assert format_ok_reply("load_calibration", reply).splitlines() == [
        "ok: calibration abc loaded; set-points change by up to 0.000 mm",
        "warning: when identified: weakly determined: … ±70.6 mm: add or spread postures",
        "warning: when identified: the base moved as a whole",
    ]
    assert format_ok_reply("load_calibration", {**reply, "warnings": []}).splitlines() == [
        "ok: calibration abc loaded; set-points change by up to 0.000 mm"]


def test_calibrate_says_the_file_keeps_its_status_and_warnings(tmp_path, nominal, leglock_campaign, capsys) -> None:
    from hexactl.adapters.cli.main import main
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.adapters.files.measurements import write_measurements

    from .conftest import NOMINAL_PATH

    data = write_measurements(tmp_path / "data.csv", leglock_campaign.data.without_lines(
        leglock_campaign.data.lines[8:]), comments=["eight postures: weakly determined"])
    output = tmp_path / "cal.toml"
    assert main(["calibrate", str(data), "--config", str(NOMINAL_PATH), "-o", str(output)]) == 0
    out = capsys.readouterr().out
    written = load_geometry(output).calibration
    assert written.status == "weakly determined" and written.warnings, written
    assert f"wrote {output}, with its status (weakly determined) and warnings: load-calibration repeats them" in out


def test_a_warning_that_is_not_one_line_of_text_is_refused_naming_it(nominal) -> None:
    """Found from outside: a file's warnings with a line end and a terminal escape
    ("\\x1b[2J", clearing the screen) were printed as they were by load-calibration and
    status."""
    import pytest
    from pydantic import ValidationError

    from hexactl.kinematics.geometry import CalibrationInfo

    fields = {"method": "full", "created": "now", "input_sha256": "0" * 64, "postures": 8, "residual_rms_mm": 0.1}
    for bad in ("first\nsecond line", "\x1b[2J\x1b[31mRED", "", "   ", "ok \u202eedoc"):  # found from outside
        with pytest.raises(ValidationError, match="a warning is one line of text, without control characters"):
            CalibrationInfo(**fields, warnings=(bad,))
    with pytest.raises(ValidationError, match="a name is one line of text"):  # printed by check, logged
        CalibrationInfo(**fields, nominal="nom\x1b[2J\ninal")
    assert CalibrationInfo(**fields, warnings=("σ ±70.6 mm · 0.66·B4.z",)).warnings == ("σ ±70.6 mm · 0.66·B4.z",)
