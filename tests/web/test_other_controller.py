"""Another controller heard on the CAN bus, on the dashboard: telemetry's
``other_controller`` was shown nowhere on the page (only the FAULT it latches while
enabled), so an operator at the page did not learn why Enable was refused, nor that
another controller had been heard a while ago.

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

from hexactl.adapters.api.messages import OtherController
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


def heard(rig: Rig, other: OtherController | None) -> None:
    """From now on the page's records say ``other`` was heard (None: as the service sends them)."""
    fields = {"other_controller": other.model_dump()} if other else None
    rig.page(f"window.hexactlTestTap.recordFields = {json.dumps(fields)};")


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
