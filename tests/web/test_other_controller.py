"""The CAN bus on the dashboard, beside the faults: another controller heard on it
(telemetry's ``other_controller`` was shown nowhere on the page, only the FAULT it latches
while enabled, so an operator at the page did not learn why Enable was refused, nor that
another controller had been heard a while ago), and the link's health (``link``: a bus
going error-passive, failed sends, a silent leg), worded as ``hexactl status`` words it.

A real headless Chromium against a real ``hexactl serve``. The built-in simulator's bus
lives inside the service's loop process, where no second controller can reach; the
field is therefore added to the service's records in the page itself, before its
scripts see them (:data:`~tests.web.test_validated_move.TAP`'s ``recordFields``), in the
shape the API's model gives it (validated here). Everything else the page shows is the service's.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from hexactl.adapters.api.messages import LinkTelemetry, OtherController
from hexactl.adapters.cli.telemetry_text import link_lines
from tests.web.test_dashboard import Rig, page_on_a_service, screenshot, wait_for
from tests.web.test_validated_move import TAP

SHOWN = """
const el = document.getElementById('other-controller');
return {hidden: el.hidden, text: el.textContent, now: el.classList.contains('now'),
        visible: el.offsetParent !== null};
"""


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("other-controller"), before_load=TAP) as rig:
        yield rig


LINK_SHOWN = """
const el = document.getElementById('link-state');
return {hidden: el.hidden, text: el.textContent, bad: el.classList.contains('bad'), visible: el.offsetParent !== null};
"""


def recorded(rig: Rig, fields: dict | None) -> None:
    """From now on the page's records carry ``fields`` (None: as the service sends them)."""
    rig.page(f"window.hexactlTestTap.recordFields = {json.dumps(fields)};")


def heard(rig: Rig, other: OtherController | None) -> None:
    """From now on the page's records say ``other`` was heard (None: as the service sends them)."""
    recorded(rig, {"other_controller": other.model_dump()} if other else None)


def shown(rig: Rig) -> dict:
    return rig.page(SHOWN)


def test_another_controller_heard_now_is_shown_beside_the_faults_and_later_as_heard_before(rig) -> None:
    assert rig.page("return window.hexactlDashboard.record.other_controller ?? null") is None
    assert shown(rig)["hidden"]

    heard(rig, OtherController(frame="SYNC", age_s=0.004))
    now = wait_for(lambda: (s := shown(rig))["visible"] and s, "the other controller shown")
    assert now["now"], now
    assert now["text"] == ("ANOTHER CONTROLLER on the bus: SYNC heard 0.00 s ago. It drives these actuators too; "
                           "Enable is refused until it stops (candump on the CAN interface shows it)."), now
    screenshot(rig.driver, "other-controller", "#controller")

    heard(rig, OtherController(frame="CMD_3 ENABLE", age_s=12.4))
    before = wait_for(lambda: not (s := shown(rig))["now"] and s, "the other controller shown as heard before")
    assert before["visible"] and before["text"] == "another controller last heard on the bus 12 s ago (CMD_3 ENABLE)"

    heard(rig, None)
    wait_for(lambda: shown(rig)["hidden"], "nothing shown once the records carry no other controller")


def test_the_links_health_shows_as_status_words_it_muted_while_active_in_red_otherwise(rig) -> None:
    """The service's own record first: its simulator's link, healthy. Then each state
    ``hexactl status`` has words for, with failures and a note, as the API's model gives them."""
    recorded(rig, None)
    live = wait_for(lambda: (s := rig.page(LINK_SHOWN))["visible"] and s, "the link's health shown")
    assert live["text"] == "CAN bus active; no send failures" and not live["bad"], live

    for state in ("warning", "passive", "bus_off", "down", "active"):
        link = LinkTelemetry(bus_state=state, send_failures=3, detail="silent legs: 4")
        recorded(rig, {"link": link.model_dump()})
        ((label, says),) = link_lines(link.model_dump())
        shown = wait_for(lambda: (s := rig.page(LINK_SHOWN))["text"] == says and s, f"the link {state} shown",
                        seen=lambda: rig.page(LINK_SHOWN))
        assert shown["visible"] and shown["bad"] == label.isupper() == (state != "active"), shown
        if state == "passive":
            assert "terminations" in says and says.endswith("; 3 send failures; silent legs: 4")
            screenshot(rig.driver, "link-passive", "#controller")
    recorded(rig, None)
