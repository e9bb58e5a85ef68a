"""The rule for text a client names things with (a sequence, a stream's source, where a
calibration came from), which the service's log and events write: one line, no control
character. A line end in it would forge the log's lines after it, an escape recolour the
terminal that shows them. The API's schema carries :data:`ONE_LINE_PATTERN`."""

from __future__ import annotations

import re

ONE_LINE_PATTERN = (r"^[^\x00-\x1f\x7f-\x9f\u061c\u200b\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069"
                    r"\ud800-\udfff\ufeff\ufff9-\ufffb]+$")
"""Non-empty, without C0 or C1 control characters, Unicode's line and paragraph separators,
its bidirectional embeddings, overrides, isolates and marks (which reorder the text printed
after them: found from outside in a calibration's warning), a zero-width space or byte
order mark (text that reads as other text), interlinear annotation characters, or a lone
surrogate (not Unicode text: a strict JSON parser refuses the message that carries it); a
JSON Schema (ECMA) regular expression too."""

_ONE_LINE = re.compile(ONE_LINE_PATTERN)


def is_one_line(text: str) -> bool:
    """``text`` keeps to :data:`ONE_LINE_PATTERN`."""
    return _ONE_LINE.fullmatch(text) is not None


def as_one_line(text: str) -> str:
    """``text`` kept to :data:`ONE_LINE_PATTERN`: each character it refuses written as its
    escape (``\\n``, ``\\x1b``), so text from elsewhere (a path) is sent as the rule wants."""
    return "".join(c if is_one_line(c) else c.encode("unicode_escape").decode("ascii") for c in text)
