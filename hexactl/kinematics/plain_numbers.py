"""How a number is written in the text hexactl reads (CSV files, a stream's text samples):
plain ASCII decimal, an optional sign, a decimal point and an exponent (``-12.5``,
``1.2e3``). What else Python's ``float`` takes (``1_000``, fullwidth or other scripts'
digits, ``0x10`` is not) is no number a CSV writer or a simulator's template produces, so
a reader refuses it as a typing error instead of guessing."""

from __future__ import annotations

import re

PLAIN_DECIMAL = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
"""A plain decimal number, whole (``fullmatch``)."""

PLAIN_DECIMAL_HINT = "write digits 0-9 with an optional sign, '.' and exponent, e.g. -12.5 or 1.2e3"
"""What to do about a number :data:`PLAIN_DECIMAL` refuses, for an error message."""
