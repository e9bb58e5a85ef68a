"""Pydantic's validation errors as a person reads them: where (``pose[5]``,
``soft_limits.upper.yaw``, ``axes.q (the key)``) and what, one line a problem. Every file,
request and message the package validates names its problems this way."""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from typing import Any, get_args

from pydantic import BaseModel, ValidationError

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


def _model_within(annotation: Any) -> type[BaseModel] | None:
    """The model a field holds: itself, or as the items of a list, a tuple or an optional;
    None where it may hold one of several (a union of models: which one's keys to list is
    not known from the location)."""
    models = _models_in(annotation)
    return models.pop() if len(models) == 1 else None


def _models_in(annotation: Any) -> set[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return {annotation}
    return set().union(*(_models_in(argument) for argument in get_args(annotation)))


def accepted_keys(model: type[BaseModel], location: Sequence[str | int]) -> tuple[str, ...]:
    """The keys the table holding ``location``'s last key takes, as written (aliases where a
    field has one), ``model`` being the outermost table's; () where the way there is not a
    chain of models."""
    for part in location[:-1]:
        if isinstance(part, int):
            continue
        field = next((f for name, f in model.model_fields.items() if part in (name, f.alias)), None)
        inner = _model_within(field.annotation) if field is not None else None
        if inner is None:
            return ()
        model = inner
    return tuple(field.alias or name for name, field in model.model_fields.items())


def unknown_key_message(key: object, accepted: Sequence[str]) -> str:
    """What to say of a key a table does not take: the nearest accepted key and all of them."""
    if not accepted:
        return "not a key here (check the spelling and the table it is in)"
    near = difflib.get_close_matches(str(key), accepted, n=1)
    guess = f"did you mean {near[0]}? " if near else ""
    return f"not a key here; {guess}the keys here are {', '.join(accepted)}"


def problem_message(problem: Mapping[str, Any], model: type[BaseModel] | None = None) -> str:
    """One pydantic problem's message, for people: an unknown key is answered with the keys
    ``model`` (the validated model, when given) takes at that place."""
    message = problem["msg"].removeprefix("Value error, ")
    if problem["type"] == "extra_forbidden" and model is not None and problem["loc"]:
        return unknown_key_message(problem["loc"][-1], accepted_keys(model, problem["loc"]))
    return message


def describe_validation_error(error: ValidationError, source: str,
                              named_items: Mapping[str, Sequence[str]] | None = None,
                              model: type[BaseModel] | None = None) -> str:
    """One line per problem, ``source: key[index]: message``, for people rather than parsers.
    ``named_items``: for a list its file writes as a table (``soft_limits.upper`` → the axes),
    the names of its items, so that one is named as written (``soft_limits.upper.yaw``).
    ``model``: the model validated, so that an unknown key is answered with the keys taken."""
    lines = []
    for problem in error.errors():
        location = validation_location(problem["loc"], named_items)
        message = problem_message(problem, model)
        if problem["type"] == "finite_number":
            message = "must be a finite number (NaN and inf are refused)"
        elif problem["type"] in _WRONG_TYPE and isinstance(problem["input"], (str, bool, float)):
            message = f"{_WRONG_TYPE[problem['type']]}, not {_as_written(problem['input'])}"
        lines.append(f"{source}: {location}: {message}" if location else f"{source}: {message}")
    return "\n".join(lines)
