"""Numbers as a file or a message writes them, for the models that read files.

Pydantic's lax mode reads the string ``"1750.0"`` as a number and ``true`` as 1: in a
geometry or a configuration either is a slip of the pen to refuse, not to read. These
types take a number only (an integer where a float is asked for: TOML writes ``3`` for
3.0), and leave the containers around them lax, so that TOML's arrays still become
tuples and strings still become enums (a model-wide ``strict=True`` would refuse both).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Strict

Number = Annotated[float, Strict()]
"""A JSON or TOML number (an integer is taken as a float); never a string or a bool."""

WholeNumber = Annotated[int, Strict()]
"""A JSON or TOML integer; never a float, a string or a bool."""

Flag = Annotated[bool, Strict()]
"""``true`` or ``false``; never a number or a string."""

SixNumbers = tuple[Number, Number, Number, Number, Number, Number]
"""One number per pose axis."""
