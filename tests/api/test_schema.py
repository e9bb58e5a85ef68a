"""docs/api.md documents the schema the code generates, and the schema is valid."""

from __future__ import annotations

from pathlib import Path

from hexactl.adapters.api.messages import COMMANDS
from hexactl.adapters.api.schema import api_schema, documented_schema

DOCUMENT = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def test_documented_schema_is_the_generated_one() -> None:
    documented = documented_schema(DOCUMENT.read_text(encoding="utf-8"))
    assert documented == api_schema(), "regenerate: python -m hexactl.adapters.api.schema --write docs/api.md"


def test_every_command_is_in_the_request_schema_and_the_document() -> None:
    mapping = api_schema()["request"]["discriminator"]["mapping"]
    assert set(mapping) == set(COMMANDS)
    text = DOCUMENT.read_text(encoding="utf-8")
    assert all(f"| `{command}` |" in text for command in COMMANDS)


def test_every_reference_resolves() -> None:
    schema = api_schema()

    def references(node):
        if isinstance(node, dict):
            if "$ref" in node:
                yield node["$ref"]
            for value in node.values():
                yield from references(value)
        elif isinstance(node, list):
            for value in node:
                yield from references(value)

    for reference in references(schema):
        assert reference.removeprefix("#/$defs/") in schema["$defs"], reference
