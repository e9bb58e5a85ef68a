"""A page in a real headless Chromium that handles telemetry more slowly than it comes, as
a browser starved of the CPU on a busy host does: it skips records, falls no further
behind than the dashboard's window of unacknowledged records, and shows no live data while
it is more than 2 s behind.

Found under load: the sockets' buffers and the browser's own queued the records such a
page had not handled yet. It fell further behind each second (10 s behind after 20 s of
handling 26 of the 50 a second) while it showed what it drew as live, and a test waiting
60 s for an event on the page failed although the page kept drawing records.

Judged by counts and by what the page said, not by how long anything took: the records
the page handles after its slow spell that the dashboard had received before the spell
ended; the page's verdict on each record it handled, against how long before (this host's
clock) the dashboard had received it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest

from hexactl.adapters.web.bridge import TELEMETRY_WINDOW
from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tools.browser import PAGE_STALE_MS, SLOWED_TELEMETRY

SLOW_MS = 100  # a record (:data:`~tools.browser.SLOWED_TELEMETRY`): 10 records a second of the 50 that come
SLOW_RECORDS = 50
AFTER = 50  # records handled after the slow spell, to see what was still queued for the page

FAR_SLOW_MS = 400  # a record: the window's 16 are 6.4 s of the page's work
FAR_SLOW_RECORDS = 25
LATE_CADENCE_MS = 1500
"""What the page may take beyond PAGE_STALE_MS to see that it is behind: it times that from its
acknowledgements, here one a record (400 ms), and a busy host delays its work some more."""


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("slow-page"), before_load=SLOWED_TELEMETRY) as rig:
        yield rig


def test_a_page_slower_than_the_records_falls_no_further_behind_than_the_window(rig) -> None:
    wait_for(lambda: rig.page("return window.hexactlDashboard.dataLoss") is None, "live data on the page")
    rig.page(f"const slow = window.hexactlTestSlow; slow.handled = []; slow.endedAt = null; slow.ms = {SLOW_MS}; "
             f"slow.remaining = {SLOW_RECORDS}")
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


def test_a_page_far_behind_the_records_shows_no_live_data_until_it_has_caught_up(rig) -> None:
    """Without this, a page handling a record in 400 ms stayed 6 s behind (the window's 16
    records of its work) and showed it as live: a record reached it every 0.4 s."""
    page = rig.page
    wait_for(lambda: page("return window.hexactlDashboard.dataLoss") is None, "live data on the page")
    page(f"const slow = window.hexactlTestSlow; slow.handled = []; slow.endedAt = null; slow.ms = {FAR_SLOW_MS}; "
         f"slow.remaining = {FAR_SLOW_RECORDS}")
    wait_for(lambda: page("return window.hexactlTestSlow.endedAt"), "the page's slow spell over")
    wait_for(lambda: page("return window.hexactlDashboard.dataLoss") is None, "live data on the page again")
    handled = page("return window.hexactlTestSlow.handled.filter((m) => m.done !== undefined)")
    behind = [m for m in handled if m["done"] - m["sent_ms"] > PAGE_STALE_MS + LATE_CADENCE_MS]
    assert len(behind) >= 5, handled  # the spell did put the page that far behind
    assert [m for m in behind if m["loss"] is None] == [], "shown live while far behind"
    shown = next(m["shown"] for m in handled if m["loss"] == "late" and "shown" in m)
    assert shown["state"] == "UNKNOWN" and re.fullmatch(r"page \d+ s behind", shown["age"]), shown
    assert "more slowly than it comes" in shown["banner"] and "HARDWARE E-STOP" in shown["banner"], shown
