"""A page in a real headless Chromium that handles telemetry more slowly than it comes, as
a browser starved of the CPU on a busy host does: it skips records, and falls no further
behind than the dashboard's window of unacknowledged records.

Found under load: the sockets' buffers and the browser's own queued the records such a
page had not handled yet. It fell further behind each second (10 s behind after 20 s of
handling 26 of the 50 a second) while it showed what it drew as live, and a test waiting
60 s for an event on the page failed although the page kept drawing records.

Judged by counts, not by how long anything took: the records the page handles after its
slow spell that the dashboard had received before the spell ended.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hexactl.adapters.web.bridge import TELEMETRY_WINDOW
from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tools.browser import SLOWED_TELEMETRY

SLOW_RECORDS = 50  # at 100 ms each (:data:`~tools.browser.SLOWED_TELEMETRY`): 10 records a second of the 50 that come
AFTER = 50  # records handled after the slow spell, to see what was still queued for the page


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("slow-page"), before_load=SLOWED_TELEMETRY) as rig:
        yield rig


def test_a_page_slower_than_the_records_falls_no_further_behind_than_the_window(rig) -> None:
    wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss") is None, "live data on the page")
    rig.page(f"window.hexactlTestSlow.remaining = {SLOW_RECORDS}")
    ended = wait_for(lambda: rig.page("return window.hexactlTestSlow.endedAt"), "the page's slow spell over")
    handled = wait_for(lambda: (h := rig.page("return window.hexactlTestSlow.handled"))
                       and sum(1 for m in h if m["at"] >= ended) >= AFTER and h, f"{AFTER} records handled after it")
    # Those still queued for the page when the spell ended: at most the window sent, the
    # newest waiting in the page's outbox and the newest not yet fanned out.
    queued = [m for m in handled if m["at"] >= ended and m["sent_ms"] < ended]
    assert len(queued) <= TELEMETRY_WINDOW + 2, queued
    numbers = [m["n"] for m in handled]
    assert numbers == sorted(set(numbers)), numbers  # each once, in order, whatever was skipped
    wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss") is None, "live data on the page again")
