"""``load_calibration`` with ``expected_id``: what a preview showed is what Apply loads.

Found from outside (the dashboard): a calibration file was previewed (its change and its
id shown), then rewritten with another calibration, and Apply, which sent only the file's
name, loaded the new one with a larger change nobody had seen. With ``expected_id`` (the id
``validate_calibration`` answered) the service refuses a file or text that now holds
another calibration (``changed_since_validation``, naming both ids), and loads nothing.
The id is ``validate_calibration``'s rule, the content hash of the calibration read
(:func:`~hexactl.adapters.files.geometry_file.geometry_id`).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hexactl.adapters.api.messages import LoadCalibrationRequest
from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.kinematics.geometry import Geometry
from tests.api.support import request

FILE = "lab.toml"


def call(service, cmd: str, **fields) -> dict:  # noqa: ANN001 - the conftest's namespace
    return request(service.api, {"v": 1, "id": 1, "cmd": cmd, **fields})


def shifted(nominal: Geometry, mm: float, name: str) -> Geometry:
    return nominal.model_copy(update={"name": name, "zero_lengths": tuple(x + mm for x in nominal.zero_lengths)})


def loads(service) -> list[str]:  # noqa: ANN001
    """The calibration ids the service asked its controller to load, in order."""
    return [arguments[1] for name, arguments in service.controller.calls if name == "load_calibration"]


@pytest.fixture
def previewed(service, nominal: Geometry) -> tuple[Geometry, str]:  # noqa: ANN001
    """A file previewed (``validate_calibration``): its calibration and the id the preview answered."""
    small = shifted(nominal, 0.2, "small")
    (Path(service.data_dir) / FILE).write_text(geometry_to_toml(small))
    preview = call(service, "validate_calibration", path=FILE)
    assert preview["ok"] and preview["valid"], preview
    assert preview["calibration_id"] == geometry_id(small)
    return small, preview["calibration_id"]


def test_a_file_rewritten_after_its_preview_is_refused_naming_both_ids_and_nothing_is_loaded(
        service, nominal, previewed) -> None:  # noqa: ANN001
    _, seen = previewed
    big = shifted(nominal, 9.0, "big")
    (Path(service.data_dir) / FILE).write_text(geometry_to_toml(big))  # another client rewrites it
    reply = call(service, "load_calibration", path=FILE, expected_id=seen)
    assert reply["ok"] is False, reply
    error = reply["error"]
    assert error["code"] == "changed_since_validation", error
    assert seen in error["message"] and geometry_id(big) in error["message"], error
    assert "preview it again" in error["message"], error
    assert error["details"] == {"expected_id": seen, "calibration_id": geometry_id(big)}, error
    assert loads(service) == []


def test_the_file_as_previewed_is_loaded(service, previewed) -> None:  # noqa: ANN001
    small, seen = previewed
    reply = call(service, "load_calibration", path=FILE, expected_id=seen)
    assert reply["ok"], reply
    assert reply["calibration_id"] == seen == geometry_id(small)
    assert loads(service) == [seen]


def test_the_same_values_in_another_layout_are_the_same_calibration(service, previewed) -> None:  # noqa: ANN001
    """The id is the content hash of the values read, the preview's own rule: a file
    rewritten with the same values (a comment added) is what was previewed."""
    small, seen = previewed
    (Path(service.data_dir) / FILE).write_text("# rewritten, same values\n" + geometry_to_toml(small))
    assert call(service, "load_calibration", path=FILE, expected_id=seen)["ok"]
    assert loads(service) == [seen]


def test_a_text_is_checked_likewise(service, nominal) -> None:  # noqa: ANN001
    small, big = shifted(nominal, 0.2, "small"), shifted(nominal, 9.0, "big")
    reply = call(service, "load_calibration", toml=geometry_to_toml(big), expected_id=geometry_id(small))
    assert reply["error"]["code"] == "changed_since_validation", reply
    assert loads(service) == []
    assert call(service, "load_calibration", toml=geometry_to_toml(small), expected_id=geometry_id(small))["ok"]
    assert loads(service) == [geometry_id(small)]


def test_without_expected_id_a_load_is_as_before(service, nominal) -> None:  # noqa: ANN001
    big = shifted(nominal, 9.0, "big")
    (Path(service.data_dir) / FILE).write_text(geometry_to_toml(big))
    assert call(service, "load_calibration", path=FILE)["ok"]
    assert loads(service) == [geometry_id(big)]


def test_a_preview_with_expected_id_says_what_the_load_would_answer(service, nominal, previewed) -> None:  # noqa: ANN001
    """``validate_calibration`` takes ``load_calibration``'s fields: with ``expected_id`` it
    answers, not valid, the refusal the load would get."""
    _, seen = previewed
    big = shifted(nominal, 9.0, "big")
    (Path(service.data_dir) / FILE).write_text(geometry_to_toml(big))
    reply = call(service, "validate_calibration", path=FILE, expected_id=seen)
    assert reply["ok"] and reply["valid"] is False, reply
    assert reply["refusal"]["code"] == "changed_since_validation", reply


@pytest.mark.parametrize("bad", ["", "x" * 65, "two words"])
def test_expected_id_is_one_word_of_at_most_64_characters(service, bad) -> None:  # noqa: ANN001
    reply = call(service, "load_calibration", toml="", expected_id=bad)
    assert reply["error"]["code"] == "invalid_request", reply
    assert loads(service) == []


def test_the_field_is_documented_in_the_schema() -> None:
    assert "expected_id" in LoadCalibrationRequest.model_json_schema()["properties"]
