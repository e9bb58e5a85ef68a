"""Pydantic's validation errors as a person reads them: where (``pose[5]``,
``soft_limits.upper.yaw``, ``axes.q (the key)``) and what, one line a problem. Every file,
request and message the package validates names its problems this way."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from pydantic import ValidationError

_WRONG_TYPE = {"float_type": "must be a number", "int_type": "must be a whole number", "bool_type": "must be true or false"}


def _as_written(value: str | bool | float) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return f'the string "{value}"' + (" (write it without quotes)" if _numeric(value) else "")


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def validation_location(location: Sequence[str | int], named_items: Mapping[str, Sequence[str]] | None = None) -> str:
    """Where a pydantic problem is, as a person writes it: ``pose[5]``, ``axes.x.amplitude``,
    ``axes.q (the key)`` for a key at fault (pydantic's ``axes.q.[key]``), and an item of a
    list named as its file writes it (``soft_limits.upper.yaw``: ``named_items``, below)."""
    text = ""
    for part in location:
        if isinstance(part, int):
            names = (named_items or {}).get(text, ())
            text += f".{names[part]}" if part < len(names) else f"[{part}]"
        elif part == "[key]":
            text += " (the key)"
        else:
            text += f".{part}" if text else part
    return text


def describe_validation_error(error: ValidationError, source: str,
                              named_items: Mapping[str, Sequence[str]] | None = None) -> str:
    """One line per problem, ``source: key[index]: message``, for people rather than parsers.
    ``named_items``: for a list its file writes as a table (``soft_limits.upper`` → the axes),
    the names of its items, so that one is named as written (``soft_limits.upper.yaw``)."""
    lines = []
    for problem in error.errors():
        location = validation_location(problem["loc"], named_items)
        message = problem["msg"].removeprefix("Value error, ")
        if problem["type"] == "finite_number":
            message = "must be a finite number (NaN and inf are refused)"
        elif problem["type"] in _WRONG_TYPE and isinstance(problem["input"], (str, bool, float)):
            message = f"{_WRONG_TYPE[problem['type']]}, not {_as_written(problem['input'])}"
        lines.append(f"{source}: {location}: {message}" if location else f"{source}: {message}")
    return "\n".join(lines)
