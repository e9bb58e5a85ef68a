from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import pytest
import tomli_w

from hexactl.adapters.files.geometry_file import (
    geometry_id,
    geometry_to_toml,
    load_geometry,
    parse_geometry,
    save_geometry,
)
from hexactl.kinematics.geometry import GeometryError

from .conftest import REPOSITORY

NOMINAL_TEXT = (REPOSITORY / "config" / "platform.toml").read_text()


def _edited(edit) -> str:
    data = tomllib.loads(NOMINAL_TEXT)
    edit(data)
    return tomli_w.dumps(data)


def test_nominal_file_loads_and_round_trips(nominal, tmp_path: Path) -> None:
    text = geometry_to_toml(nominal)
    assert parse_geometry(text, "round trip") == nominal
    saved = save_geometry(nominal, tmp_path / "copy.toml")
    assert load_geometry(saved) == nominal
    assert geometry_id(load_geometry(saved)) == geometry_id(nominal)


def test_saving_never_overwrites_without_being_told(nominal, tmp_path: Path) -> None:
    target = tmp_path / "cal.toml"
    target.write_text("precious")
    with pytest.raises(FileExistsError, match="--force"):
        save_geometry(nominal, target)
    assert target.read_text() == "precious"
    save_geometry(nominal, target, overwrite=True)
    assert load_geometry(target) == nominal
    assert [p.name for p in tmp_path.iterdir()] == ["cal.toml"]  # no temporary left behind


def _del(key):
    return lambda d: d.pop(key)


def _set(path, value):
    def edit(data):
        node = data
        for part in path[:-1]:
            node = node[part]
        node[path[-1]] = value
    return edit


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (_del("zero_lengths"), r"zero_lengths: Field required"),
        (_del("limits"), r"limits: Field required"),
        (_set(["base_joints"], [[1.0, 2.0, 3.0]] * 5), r"base_joints"),
        (_set(["platform_joints", 2], [1.0, 2.0]), r"platform_joints\[2\]"),
        (_set(["zero_lengths", 3], float("nan")), r"zero_lengths\[3\]: must be a finite number"),
        (_set(["home", 2], float("inf")), r"home\[2\]: must be a finite number"),
        (_set(["base_joints", 1], [1448.889, -388.229, 0.0]), r"base_joints: joints 1 and 2 coincide"),
        # every length in metres: the joints end up a fraction of a "mm" apart
        (lambda d: d.update({key: [[v / 1000.0 for v in joint] for joint in d[key]]
                             for key in ("base_joints", "platform_joints")}),
         r"base_joints: joints 1 and 2 coincide \(0.776 mm apart, less than 1 mm\): .* in mm, not metres"),
        (_set(["limits", "stroke"], [0.0, 100.0]), r"limits.stroke: leg 1 needs sensor reading .* outside the stroke"),
        # the stroke is named, but a typo in the leg's own values is as likely: both are said
        (_set(["zero_lengths", 2], 17500.0),
         r"limits.stroke: leg 3 needs sensor reading -15390.023 mm in the zero posture, outside the stroke \[0.0, 850.0\]: "
         r"check the stroke, and zero_lengths\[2\], base_joints\[2\], platform_joints\[2\] and home \(mm, deg\)$"),
        (_set(["zero_lengths", 0], 1e300), r"leg 1 needs sensor reading -1e\+300 mm in the zero posture"),
        (_set(["limits", "stroke"], [500.0, 100.0]), r"stroke: min 500.0 must be below max 100.0"),
        (_set(["limits", "pose_min", 0], 10.0), r"x range \[10.0, 610.0\] must contain the zero posture"),
        # a threshold below the zero posture's own conditioning refuses every move, the way home too
        (_set(["limits", "max_jacobian_condition"], 5.0),
         r"limits.max_jacobian_condition: the zero posture's Jacobian condition is 7.6, above this limit of 5: every "
         r"pose near it would be refused as near-singular"),
        (_set(["zero_lengths", 0], -5.0), r"zero_lengths: leg 1 has non-positive zero length"),
        (_set(["measurement", "feature_points"], [[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]]), r"collinear"),
        # a noise far below a nanometre overflowed the identification's weights 1/σ² (a traceback)
        (_set(["measurement", "point_sigma_mm"], 1e-200),
         r"measurement.point_sigma_mm: 1e-200 is not a noise \(1σ\) from 1e-06 to 1000 mm, a nanometre to a metre"),
        (_set(["measurement", "feature_point_sigma_mm"], 1e-200),
         r"measurement.feature_point_sigma_mm: 1e-200 is not a noise .*; or 0: known exactly$"),
        (_set(["limits", "typo_key"], 1.0), r"limits.typo_key: not a key here; the keys here are stroke, base_cone_deg, .*"),
        (_set(["limits", "max_jacobian_conditon"], 1.0),
         r"limits.max_jacobian_conditon: not a key here; did you mean max_jacobian_condition\?"),
        (_set(["zero_lengths", 0], "long"), r'zero_lengths\[0\]: must be a number, not the string "long"$'),
        # numbers are numbers: a quoted one or a bool is a slip to refuse, not to read
        (_set(["zero_lengths", 0], "1750.0"), r'zero_lengths\[0\]: must be a number, not the string "1750.0" '
                                              r"\(write it without quotes\)"),
        (_set(["zero_lengths", 0], True), r"zero_lengths\[0\]: must be a number, not true"),
        (_set(["base_joints", 1, 2], "0"), r"base_joints\[1\]\[2\]: must be a number"),
        (_set(["limits", "leg_velocity_mm_s"], "100"), r"limits.leg_velocity_mm_s: must be a number"),
        (_set(["limits", "stroke", 1], False), r"limits.stroke\[1\]: must be a number, not false"),
        (_set(["home", 0], "0"), r"home\[0\]: must be a number"),
        # Limits the actuators cannot follow: the loop would plan and start a move, then have
        # its set-points refused mid-motion (the actuator's fault, or the CAN frames cannot
        # carry them: FAULT, legs stopped wherever they were).
        (_set(["limits", "stroke"], [0.0, 1500.0]),
         r"limits.stroke: \[0.0, 1500.0\] mm reaches beyond the actuators' stroke, 0 to 1300 mm "
         r"\(firmware_proto/PROTOCOL.md sections 1 and 4\): they would refuse the set-points beyond it mid-motion; "
         r"it is in mm \(not µm\): give the actuators' soft limits"),
        (_set(["limits", "stroke"], [0.0, 850000.0]), r"limits.stroke: \[0.0, 850000.0\] mm reaches beyond"),  # µm
        (_set(["limits", "stroke"], [-100.0, 850.0]), r"limits.stroke: \[-100.0, 850.0\] mm reaches beyond"),
        (_set(["limits", "leg_velocity_mm_s"], 24000.0),  # mm/min written for mm/s
         r"limits.leg_velocity_mm_s: 24000 mm/s is beyond the speeds the actuators' feedback carries \(3276.7 mm/s, "
         r"firmware_proto/PROTOCOL.md section 3\): it is in mm/s"),
        (_set(["calibration"], {"method": "full", "created": "2026-11-26", "input_sha256": "0", "postures": 60,
                                "residual_rms_mm": 0.02, "zero_lengths_std_mm": [0.01, 0.01, -0.01, 0.01, 0.01, 0.01]}),
         r"calibration.zero_lengths_std_mm: a standard deviation cannot be negative, got -0.01: the file was edited"),
        # symmetric with positive variances, yet a combination's variance is negative: the
        # controller would predict no error there, and any tolerance would pass
        (_set(["calibration"], {"method": "full", "created": "2026-11-26", "input_sha256": "0", "postures": 60,
                                "residual_rms_mm": 0.02,
                                "parameter_covariance": [[1.0 if i == j else 2.0 if {i, j} == {0, 1} else 0.0
                                                          for j in range(42)] for i in range(42)]}),
         r"calibration.parameter_covariance: is not positive semi-definite \(eigenvalue -1 mm²"),
        # with the scale errors the units mix: the eigenvalue is not in mm²
        (_set(["calibration"], {"method": "full", "created": "2026-11-26", "input_sha256": "0", "postures": 60,
                                "residual_rms_mm": 0.02,
                                "parameter_covariance": [[1.0 if i == j else 2.0 if {i, j} == {0, 47} else 0.0
                                                          for j in range(48)] for i in range(48)]}),
         r"calibration.parameter_covariance: is not positive semi-definite \(eigenvalue -1, in the parameters' mixed "
         r"units \(mm, mm per metre\): a negative variance"),
        (_set(["calibration"], {"method": "full", "created": "2026-11-26", "input_sha256": "0", "postures": 60.0,
                                "residual_rms_mm": 0.02}), r"calibration.postures: must be a whole number, not 60.0"),
    ],
)
def test_bad_geometry_files_are_refused_naming_the_key(edit, expected) -> None:
    with pytest.raises(GeometryError, match=expected) as refused:
        parse_geometry(_edited(edit), "bad.toml")
    assert str(refused.value).startswith("bad.toml: ")


def test_unreadable_and_invalid_toml_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(GeometryError, match="missing.toml: no such file: check the name"):
        load_geometry(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("base_joints = [[1, 2, 3]\n")
    with pytest.raises(GeometryError, match="broken.toml: not valid TOML"):
        load_geometry(broken)
    # found from outside: a file caught while being written said six keys were each "Field required"
    for text, said in (("", "empty (no key at all: being written?)"), ("# only a comment\n", "empty (no key at all)")):
        with pytest.raises(GeometryError, match=re.escape(f"cal.toml: {said}")) as refused:
            parse_geometry(text, "cal.toml")
        assert "Field required" not in str(refused.value)


def test_saved_files_get_ordinary_permissions(nominal, tmp_path: Path) -> None:
    umask = os.umask(0)
    os.umask(umask)
    saved = save_geometry(nominal, tmp_path / "cal.toml")
    assert saved.stat().st_mode & 0o777 == 0o666 & ~umask


def test_the_id_is_a_hash_of_the_values_not_of_the_text(nominal) -> None:
    reordered = "\n".join(
        line for line in NOMINAL_TEXT.splitlines() if not line.startswith("#")  # no comments
    ).replace("zero_lengths = [1750.0, 1750.0, 1750.0, 1750.0, 1750.0, 1750.0]",
              "zero_lengths = [1750, 1750, 1.75e3, 1750.000, 1750, 1750]")  # other spellings
    reordered = reordered.replace("home = [0.0, 0.0, 2000.0, 0.0, 0.0, 0.0]", "")
    reordered = "home = [-0.0, 0, 2000, 0.0, -0.0, 0]  # a comment\n" + reordered  # moved, -0.0
    other = parse_geometry(reordered, "other layout")
    assert other == nominal
    assert geometry_id(other) == geometry_id(nominal)
    assert len(geometry_id(nominal)) == 16 and int(geometry_id(nominal), 16) >= 0


def test_different_values_get_different_ids(nominal) -> None:
    moved = nominal.model_copy(update={"zero_lengths": (1750.0,) * 5 + (1750.001,)})
    renamed = nominal.model_copy(update={"name": "another"})
    assert len({geometry_id(nominal), geometry_id(moved), geometry_id(renamed)}) == 3
