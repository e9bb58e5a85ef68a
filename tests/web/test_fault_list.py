"""The dashboard's fault list, in a real headless Chromium against a real ``hexactl serve``.

Found from outside: a link lost latches the same fault on all six legs at once, and the
page listed six near-identical red lines that pushed the panels out of view, with no word
on what to do next. Judged by the page's text, never by how long anything took.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tests.web import test_validated_move as moves


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("fault-list")) as rig:
        wait_for(lambda: moves.live(rig), "live data on the page")
        yield rig


def lines(rig: Rig) -> list[dict]:
    return rig.page("return [...document.querySelectorAll('#faults li')].map((li) => "
                    "({code: li.querySelector('b')?.textContent ?? null, text: li.textContent, title: li.title, "
                    "advice: li.classList.contains('advice')}))")


def test_faults_of_one_code_on_several_legs_are_one_line_naming_every_leg(rig) -> None:
    faults = [{"code": "actuator_fault", "message": f"leg {leg} reports FAULT, faults: comm_timeout", "leg": leg}
              for leg in (3, 1, 2, 6, 5, 4)]
    faults += [{"code": "estop", "message": "E-stop from page"}, {"code": "estop", "message": "E-stop from cli"},
               {"code": "link_failed", "message": "bus BUS-OFF"}]
    shown = rig.driver.execute_async_script("""
        const [faults, done] = arguments;
        import('/static/faults.js').then(({ groupFaults, faultLine, faultAdvice }) => done({
            lines: groupFaults(faults).map((group) => [group.code, faultLine(group), group.all.length]),
            fault: faultAdvice('fault'), estop: faultAdvice('estop'), enabled: faultAdvice('enabled') }));
    """, faults)
    assert shown["lines"] == [
        ["actuator_fault", "leg 3 reports FAULT, faults: comm_timeout (leg 3; also legs 1, 2, 4, 5, 6)", 6],
        ["estop", "E-stop from page, and 1 more", 2],
        ["link_failed", "bus BUS-OFF", 1],
    ]
    assert shown["fault"] == "Remove the cause, then Reset (the controller ends disabled), then Enable."
    assert shown["estop"].startswith("Once the cause of the E-stop is gone: Reset")
    assert shown["enabled"] == ""


def test_a_latched_estop_is_listed_with_what_to_do_next_and_reset_clears_both(rig) -> None:
    def scenario() -> None:
        rig.enabled_from_the_page()
        assert lines(rig) == []
        rig.click("#estop")
        wait_for(lambda: rig.status()["state"] == "estop", "the E-stop carried out")
        wait_for(lambda: len(lines(rig)) == 2, "the fault and the advice listed", seen=lambda: lines(rig))
        estop, advice = lines(rig)
        assert estop["code"] == "estop" and not estop["advice"] and "dashboard" in estop["title"], estop
        assert advice["advice"] and advice["text"].startswith("Once the cause of the E-stop is gone: Reset"), advice
        rig.click("#reset")
        wait_for(lambda: rig.status()["state"] == "disabled", "reset")
        wait_for(lambda: lines(rig) == [], "the list emptied", seen=lambda: lines(rig))

    rig.scenario(scenario)
