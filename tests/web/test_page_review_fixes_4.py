"""Defects outside reviews found, in a real headless Chromium against a real ``hexactl serve``:

- a link lost latches the same fault on all six legs at once, and the page listed six
  near-identical red lines that pushed the panels out of view, with no word on what to do
  next;
- a calibration written "weakly determined" (a combination known to ±70 mm) was previewed
  and applied as any other: what its identification warned of was in no reply.

Judged by the page's text, never by how long anything took.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from selenium.webdriver.support.select import Select

from hexactl.adapters.files.geometry_file import geometry_id, geometry_to_toml
from hexactl.kinematics.geometry import CalibrationInfo
from tests.web.test_dashboard import Rig, page_on_a_service, wait_for
from tests.web import test_page_review_fixes as preview
from tests.web import test_validated_move as moves


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> Iterator[Rig]:
    with page_on_a_service(tmp_path_factory.mktemp("review-fixes-4")) as rig:
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


def test_a_calibration_previewed_applied_and_rolled_back_to_shows_what_its_identification_warned_of(rig) -> None:
    warned = ("weakly determined: the worst combination 0.66·B4.z −0.66·zero4 is known to ±70.6 mm: add or spread "
              "postures")
    info = CalibrationInfo(method="full", created="2026-01-01T00:00:00+00:00", input_sha256="0" * 64, postures=8,
                           residual_rms_mm=0.1, status="weakly determined", warnings=(warned,))
    weak = preview.calibrated(0.2, "review weak").model_copy(update={"calibration": info})
    said = f"warning, when identified: {warned}"

    def shown(selector: str) -> tuple[list[str], str]:
        """The result's classes and text, read at once: read one after the other, a reply that
        came between them paired the last result's class with this one's text."""
        return tuple(rig.page(f"const e = document.querySelector({selector!r}); "
                              "return [e.className.split(' '), e.textContent]"))

    def scenario() -> None:
        rig.at_rest_disabled()
        try:
            (rig.directory / "calibrations" / preview.FILE).write_text(geometry_to_toml(weak))
            rig.click("#calibration-refresh")
            wait_for(lambda: any(o.get_attribute("value") == preview.FILE
                                 for o in Select(rig.element("#calibration-files")).options), "the file in the list")
            Select(rig.shown("#calibration-files")).select_by_value(preview.FILE)
            preview.cleared(rig, "#calibration-change")
            rig.click("#calibration-preview")
            classes, text = wait_for(lambda: (s := shown("#calibration-change"))[1] not in ("", "previewing…") and s,
                                     "the preview", seen=lambda: shown("#calibration-change"))
            assert "cautioned" in classes and geometry_id(weak) in text and said in text, (classes, text)
            assert preview.apply_enabled(rig)  # a warning, not a refusal: the operator decides
            preview.cleared(rig, "#calibration-result")
            rig.click("#calibration-apply")
            classes, text = wait_for(lambda: (s := shown("#calibration-result"))[1] and s, "Apply's answer")
            assert "cautioned" in classes and said in text, (classes, text)
            assert rig.status()["calibration_id"] == geometry_id(weak)
            rig.client.call("load_calibration", toml=geometry_to_toml(preview.calibrated(0.1, "review plain")))
            preview.cleared(rig, "#calibration-result")
            rig.confirm("#calibration-rollback")
            classes, text = wait_for(lambda: (s := shown("#calibration-result"))[1] and s, "Roll back's answer")
            assert "cautioned" in classes and said in text, (classes, text)
            preview.cleared(rig, "#calibration-result")
            rig.confirm("#calibration-rollback")  # back to the nominal geometry: no warnings
            classes, text = wait_for(lambda: (s := shown("#calibration-result"))[1] and s, "Roll back's answer")
            assert "valid" in classes and "warning" not in text, (classes, text)
        finally:
            preview.back_to_nominal(rig)

    rig.scenario(scenario)
