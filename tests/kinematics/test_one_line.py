"""The one-line rule for names the log writes, and text from elsewhere kept to it."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from hexactl.kinematics.one_line import as_one_line, is_one_line


@given(st.text(min_size=1))
def test_any_text_kept_to_the_rule_is_one_line_and_one_line_text_is_kept_as_it_is(text: str) -> None:
    kept = as_one_line(text)
    assert is_one_line(kept)
    assert (kept == text) == is_one_line(text)


def test_a_line_end_an_escape_and_a_unicode_separator_are_written_as_escapes() -> None:
    """A campaign sends its folder's path as a calibration's source: a line end in it would
    have made the service refuse the load at the campaign's end, after hours of measuring."""
    assert as_one_line("/data/run\n2/ü.toml\x1b[31m\u2028") == "/data/run\\n2/ü.toml\\x1b[31m\\u2028"
    assert not is_one_line("") and not is_one_line("a\tb") and is_one_line("Prüfung 2 – ε")
    # a right-to-left override reorders what is printed after it (found from outside)
    assert not is_one_line("ok \u202eedoc") and not is_one_line("a\u2066b") and is_one_line("שלום")
