"""The page's script repeats a few of the service's rules as numbers of its own (a browser
cannot import Python): each must stay what the Python side says, or the page would judge a
record differently from the service and the dashboard."""

from __future__ import annotations

import pytest

from hexactl.adapters.cli.jog_commands import RENEWALS_PER_DEADMAN
from hexactl.adapters.web.bridge import TELEMETRY_WINDOW
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S, REPORT_SILENT_S
from tools.browser import page_constant


@pytest.mark.parametrize(("name", "python_value"), [
    ("REPORT_SILENT_S", REPORT_SILENT_S),
    ("OTHER_CONTROLLER_WINDOW_S", OTHER_CONTROLLER_WINDOW_S),
])
def test_the_page_judges_a_record_by_the_services_own_windows(name: str, python_value: float) -> None:
    assert page_constant(name) == python_value


def test_the_page_acknowledges_within_the_window_the_dashboard_sends_it_unacknowledged() -> None:
    """At ACK_EVERY ≥ TELEMETRY_WINDOW a page that handles records as they come would wait
    for its next record while the dashboard waits for its acknowledgement: it stalls."""
    assert 1 <= page_constant("ACK_EVERY") < TELEMETRY_WINDOW


def test_the_page_renews_a_held_jog_as_often_as_the_command_line_does() -> None:
    assert page_constant("RENEWALS_PER_DEADMAN") == RENEWALS_PER_DEADMAN


def test_a_name_the_page_does_not_declare_is_an_error_not_a_default() -> None:
    with pytest.raises(LookupError, match="NO_SUCH_RULE"):
        page_constant("NO_SUCH_RULE")
