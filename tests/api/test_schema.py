"""docs/api.md documents the schema the code generates, and the schema is valid."""

from __future__ import annotations

import re
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


def keyword_values(node, keyword: str):
    """Every string value of ``keyword`` anywhere in the schema ``node``."""
    if isinstance(node, dict):
        if isinstance(node.get(keyword), str):
            yield node[keyword]
        for value in node.values():
            yield from keyword_values(value, keyword)
    elif isinstance(node, list):
        for value in node:
            yield from keyword_values(value, keyword)


def test_every_reference_resolves() -> None:
    schema = api_schema()
    for reference in keyword_values(schema, "$ref"):
        assert reference.removeprefix("#/$defs/") in schema["$defs"], reference


def test_every_error_code_is_documented() -> None:
    """Found from outside: ``invalid_argument`` reached clients and was in neither table."""
    from hexactl.adapters.api.wire import ErrorCode as ApiErrorCode
    from hexactl.control.results import ErrorCode as ControllerErrorCode

    text = DOCUMENT.read_text(encoding="utf-8").split("### Error codes", 1)[1].split("## Telemetry", 1)[0]
    missing = [code.value for code in (*ApiErrorCode, *ControllerErrorCode) if f"`{code.value}`" not in text]
    assert not missing, f"error codes not in docs/api.md's Error codes: {missing}"


def _table_rows(section: str) -> dict[str, str]:
    """The rows of a section's tables by the names in their first cell (backquoted)."""
    rows: dict[str, str] = {}
    for line in section.splitlines():
        first, _, rest = line.removeprefix("| ").partition(" | ")
        if line.startswith("| `") and rest:
            rows.update(dict.fromkeys(re.findall(r"`([a-z_]+)`", first), rest))
    return rows


def test_every_request_field_and_telemetry_field_is_in_its_table() -> None:
    """Found from outside: ``move``'s ``tolerance_mm``, the ``predicted_accuracy`` of
    ``status`` and ``validate_pose`` and telemetry's ``jog`` were in the schema only."""
    from hexactl.adapters.api.messages import REPLY_MODELS, REQUEST_MODELS, OkReply, Telemetry

    text = DOCUMENT.read_text(encoding="utf-8")
    commands = _table_rows(text.split("### Commands", 1)[1].split("**Sequences.**", 1)[0])
    missing = []
    for model in REQUEST_MODELS:
        command = model.model_fields["cmd"].annotation.__args__[0]
        fields = [name for name in model.model_fields if name not in ("v", "id", "cmd", "deadline_ms", "expires_at")]
        row = commands[command]
        if not row.startswith("as "):  # "as move": the same fields
            missing += [f"{command}: {name}" for name in fields if f"`{name}`" not in row.split(" | ")[0]]
        reply = REPLY_MODELS.get(command)
        if reply is not None and "the side file's fields" not in row:
            missing += [f"{command} reply: {name}" for name in reply.model_fields
                        if name not in OkReply.model_fields and f"`{name}`" not in row.split(" | ")[-1]]
    telemetry = _table_rows(text.split("## Telemetry", 1)[1].split("## Command line", 1)[0])
    missing += [f"telemetry: {name}" for name in Telemetry.model_fields if name not in telemetry]
    assert not missing, f"not in docs/api.md's tables: {missing}"


def test_every_pattern_is_one_a_re2_engine_compiles() -> None:
    """Clients generate validators from the schema, many with an RE2-family engine (Go, Rust,
    pydantic-core's default), which has no lookaround, backreference or inline flag: one such
    pattern makes the whole schema unusable to them (found by a reviewer: a lookahead)."""
    found = list(keyword_values(api_schema(), "pattern"))
    assert found and all(re.compile(pattern) for pattern in found)
    assert [pattern for pattern in found if "(?" in pattern or re.search(r"\\[1-9]", pattern)] == []
