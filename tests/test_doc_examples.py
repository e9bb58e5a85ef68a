"""The example files the documentation shows are ones hexactl takes: a reader who copies
one gets a file that parses, not a refusal (docs/calibration.md, docs/api.md)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hexactl.adapters.api.messages import REPLY_MODELS, ErrorReply, OkReply
from hexactl.adapters.api.wire import decode_request
from hexactl.adapters.files.geometry_file import load_geometry
from hexactl.adapters.files.instrument_file import parse_instrument
from hexactl.adapters.files.measurements import parse_measurements
from hexactl.adapters.files.sequence_file import sequence_from_toml
from hexactl.calibration.data import screen_measurements

ROOT = Path(__file__).resolve().parents[1]


def fenced_blocks(document: str, language: str = "") -> list[str]:
    """The text of each fenced block of ``docs/DOCUMENT`` opened with ```LANGUAGE."""
    text = (ROOT / "docs" / document).read_text(encoding="utf-8")
    return re.findall(rf"^```{language}\n(.*?)^```$", text, flags=re.MULTILINE | re.DOTALL)


def test_the_measurement_file_example_parses_and_passes_screening() -> None:
    nominal = load_geometry(ROOT / "config" / "platform.toml")
    [example] = [block for block in fenced_blocks("calibration.md") if block.startswith("# leg 1 locked")]
    parsed = parse_measurements(example, "calibration.md", len(nominal.measurement.feature_points))
    assert parsed.problems == () and len(parsed.data) == 1
    assert screen_measurements(parsed.data, np.array(nominal.measurement.feature_points),
                               nominal.measurement.point_sigma_mm) == ()


def test_the_instrument_file_example_parses() -> None:
    [example] = [block for block in fenced_blocks("calibration.md", "toml") if block.startswith('kind = "theodolites"')]
    parse_instrument(example, "calibration.md")


def test_the_sequence_file_example_parses() -> None:
    [example] = [block for block in fenced_blocks("api.md", "toml") if "[[waypoint]]" in block]
    sequence = sequence_from_toml(example, "api.md")
    assert sequence.name == "z_steps" and len(sequence.waypoints) == 2


def json_examples(document: str) -> list[dict]:
    """The JSON objects the ```json blocks of ``docs/DOCUMENT`` show, one a line (a line
    that does not start with ``{`` goes on the one before), in order; abridged ones (with
    "…") and the generated schema left out."""
    examples = []
    for block in fenced_blocks(document, "json"):
        if '"$schema"' in block:
            continue
        lines: list[str] = []
        for line in block.splitlines():
            if line.startswith("{") or not lines:
                lines.append(line)
            else:
                lines[-1] += "\n" + line
        examples += [json.loads(line) for line in lines if "…" not in line]
    return examples


@pytest.mark.parametrize("document", ["api.md", "stream.md"])
def test_the_api_examples_are_requests_the_service_takes_and_replies_it_sends(document: str) -> None:
    """Found from outside: stream.md's stream_open reply lacked the envelope every reply
    has, and api.md's jog release the fields its reply carries as null; an integrator
    writes a parser from these."""
    commands: dict[object, str] = {}  # the command of the latest request with each id: its reply follows it
    examples = json_examples(document)
    assert examples
    for example in examples:
        text = json.dumps(example)
        if "cmd" in example:
            decode_request(text.encode())
            commands[example["id"]] = example["cmd"]
        elif example["ok"]:
            REPLY_MODELS.get(commands[example["id"]], OkReply).model_validate_json(text)
        else:
            ErrorReply.model_validate_json(text)
