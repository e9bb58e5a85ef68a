"""A page in a real headless Chromium whose clock is an hour off the dashboard host's, as a
browser on another host reached through an ssh tunnel may be: the record → drawing latency
it shows is on the dashboard's clock, measured from its acknowledgements' round trips, not
off by the hour (it was: the page took the dashboard's send time against its own clock).

Judged by the hour, never by how long anything took: a latency is far below it however
busy the host is."""

from __future__ import annotations

import statistics
from collections.abc import Iterator

import pytest

from tests.web.test_dashboard import Rig, page_on_a_service, wait_for

HOUR_MS = 3_600_000
AN_HOUR_AHEAD = f"(() => {{ const real = Date.now.bind(Date); Date.now = () => real() + {HOUR_MS}; }})();"
DRAWN = 50  # latencies, one a record drawn


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("page-clock"), before_load=AN_HOUR_AHEAD) as rig:
        yield rig


def test_the_latency_a_page_on_another_clock_shows_is_on_the_dashboards(rig) -> None:
    assert rig.page("return Date.now()") - rig.page("return performance.timeOrigin + performance.now()") > HOUR_MS / 2
    latencies = wait_for(lambda: (v := rig.page("return window.hexactlDashboard.latencies()")) and len(v) >= DRAWN and v,
                         f"{DRAWN} records drawn")
    assert abs(statistics.median(latencies)) < HOUR_MS / 60, latencies  # a minute: any busy host's, not the hour
    assert "ms" in rig.page("return document.getElementById('latency-summary').textContent")
