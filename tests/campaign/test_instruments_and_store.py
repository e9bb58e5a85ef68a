"""The campaign's instruments (file, terminal) and its directory (plan, saved rows, resume checks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hexactl.application.campaign import instruments
from hexactl.application.campaign.driver import CampaignError
from hexactl.adapters.api.client import CommandError
from hexactl.application.campaign.instruments import (
    CsvInstrument,
    InstrumentError,
    PromptInstrument,
    ServiceInstrument,
    open_instrument,
)
from hexactl.application.campaign.store import (
    MEASUREMENTS_FILE,
    PLAN_FILE,
    VALIDATION_FILE,
    VALIDATION_STEPS,
    CampaignStore,
    DirectoryError,
)
from hexactl.adapters.files.measurements import read_measurements
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.kinematics.rotation import rotation_matrix
from hexactl.calibration.campaign import CampaignDesign

DESIGN = CampaignDesign(postures_per_leg=2, candidates=100, seed=1)


def points_at(geometry, relative) -> np.ndarray:
    """The feature points, fixed frame, of the pose ``relative`` (mm, deg)."""
    absolute = absolute_from_relative(geometry.home, relative)
    return np.array(geometry.measurement.feature_points) @ rotation_matrix(*absolute[3:]).T + absolute[:3]


# -- instruments ---------------------------------------------------------------------


def tracker_rows(geometry, heights) -> str:
    """Rows of a tracker's export: the feature points at z = each of ``heights``, and a column of its own."""
    return "".join(",".join(str(v) for v in points_at(geometry, [0, 0, z, 0, 0, 0]).ravel()) + ",ann\n" for z in heights)


TRACKER_HEADER = "# laser tracker export\np1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z,operator\n"


def test_instrument_file_rows_are_the_measurements_in_order(nominal, tmp_path, monkeypatch) -> None:
    path = tmp_path / "tracker.csv"
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(2)))  # a resumed campaign's two measurements
    instrument = CsvInstrument(path, 3)
    monkeypatch.setattr(instruments.time, "sleep",  # the tracker measures the third once asked
                        lambda seconds: path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(3))))
    np.testing.assert_allclose(instrument.measure(2, "third"), points_at(nominal, [0, 0, 2, 0, 0, 0]))


def test_a_row_written_while_the_platform_moved_is_refused(nominal, tmp_path, monkeypatch) -> None:
    """The docs said a row there before the platform reached its posture is refused; one
    appended after the file was opened, while the platform moved, was taken for it."""
    path = tmp_path / "tracker.csv"
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(1)))
    instrument = CsvInstrument(path, 3)
    monkeypatch.setattr(instruments.time, "sleep",
                        lambda seconds: path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(2))))
    np.testing.assert_allclose(instrument.measure(1, "posture 1"), points_at(nominal, [0, 0, 1, 0, 0, 0]))
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(3)))  # triggered early: the platform still moves
    with pytest.raises(InstrumentError, match=r"rows 3-3 \(lines 5-5\) were there before the platform was at rest at "
                                              r"posture 2: .* measured while it moved there"):
        instrument.measure(2, "posture 2")


def test_a_row_measured_for_a_measurement_not_kept_is_never_taken_for_another(nominal, tmp_path, monkeypatch) -> None:
    path = tmp_path / "tracker.csv"
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(3)))  # the third: a measurement a fault interrupted
    with pytest.raises(InstrumentError, match=rf"rows 3-3 \(lines 5-5\) were there before the platform was at rest at "
                                              rf"posture 1: the campaign kept 2 .*delete them from {path}"):
        CsvInstrument(path, 3).measure(2, "posture 1")  # resumed: the posture is measured again, not that row taken
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(2)))
    instrument = CsvInstrument(path, 3)
    monkeypatch.setattr(instruments.time, "sleep",
                        lambda seconds: path.write_text(TRACKER_HEADER + tracker_rows(nominal, [0, 1, 20])))
    np.testing.assert_allclose(instrument.measure(2, "posture 1"), points_at(nominal, [0, 0, 20, 0, 0, 0]))
    with pytest.raises(InstrumentError, match="rows 3-3 .* were there before the platform was at rest at posture 1"):
        instrument.measure(2, "posture 1")  # not kept (a fault), measured again in the same run: not that row again
    monkeypatch.setattr(instruments.time, "sleep",
                        lambda seconds: path.write_text(TRACKER_HEADER + tracker_rows(nominal, [0, 1, 30])))
    path.write_text(TRACKER_HEADER + tracker_rows(nominal, range(2)))  # the operator deletes it, then measures
    np.testing.assert_allclose(instrument.measure(2, "posture 1"), points_at(nominal, [0, 0, 30, 0, 0, 0]))


def test_a_bad_instrument_file_is_refused_naming_every_bad_line(tmp_path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("p1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z\n"
                    "1,2,3,4,5,6,7,8,9\n"
                    "# a comment\n"
                    "1,2,x,4,5,6,7,8,9\n"
                    "1,2,3,4,5,6,7,8\n"
                    "1,2,3,4,5,6,7,8,nan\n")
    with pytest.raises(InstrumentError) as refused:
        CsvInstrument(path, 3)
    message = str(refused.value)
    assert "line 4: p1_z 'x' is not a number" in message
    assert "line 5: has 8 fields, the header has 9" in message
    assert "line 6: p3_z is nan (not a finite number)" in message
    assert "line 2" not in message
    (tmp_path / "few.csv").write_text("p1_x,p1_y,p1_z\n1,2,3\n")
    with pytest.raises(InstrumentError, match="1 feature point"):
        CsvInstrument(tmp_path / "few.csv", 3)
    with pytest.raises(InstrumentError, match="missing.csv: no such file: check the name"):
        CsvInstrument(tmp_path / "missing.csv", 3)


def test_the_campaign_waits_for_a_row_the_instrument_has_not_written_yet(nominal, tmp_path, monkeypatch) -> None:
    path = tmp_path / "live.csv"
    header = "p1_x,p1_y,p1_z,p2_x,p2_y,p2_z,p3_x,p3_y,p3_z\n"
    path.write_text(header)
    said: list[str] = []
    instrument = CsvInstrument(path, 3, said.append)
    row = ",".join(str(v) for v in points_at(nominal, [5, 0, 0, 0, 0, 0]).ravel()) + "\n"
    monkeypatch.setattr(instruments.time, "sleep", lambda seconds: path.write_text(header + row))  # the tracker logs
    np.testing.assert_allclose(instrument.measure(0, "posture 1"), points_at(nominal, [5, 0, 0, 0, 0, 0]))
    assert said == [f"waiting for row 1 of {path} (posture 1): measure now"]


def test_prompt_asks_again_for_a_typo_and_for_a_missighted_target(nominal) -> None:
    exact = points_at(nominal, [0, 0, 10, 0, 0, 0])
    typed = [f"{x} {y} {z}" for x, y, z in exact]
    mis_sighted = [typed[0], typed[1], f"{exact[2][0] + 5} {exact[2][1]} {exact[2][2]}"]
    answers = iter(["1 2", *mis_sighted, typed[0], "a b c", typed[1], ", ".join(typed[2].split())])
    said: list[str] = []
    instrument = PromptInstrument(nominal, ask=lambda prompt: next(answers), say=said.append)
    np.testing.assert_allclose(instrument.measure(0, "posture 1"), exact)
    assert "'1 2' is not three numbers" in said[1]
    assert "distance p1-p3" in said[2] and "measure again" in said[2]
    assert "'a b c' is not three numbers" in said[3]


class Refusing:
    """A service whose ``measure`` is refused ``code``."""

    def __init__(self, code: str, message: str) -> None:
        self.code, self.message = code, message

    def call(self, cmd: str, **fields: object) -> dict:
        raise CommandError(self.code, self.message)


@pytest.mark.parametrize(("code", "message", "said"), [
    ("no_instrument", "this service has no measuring instrument", r"\(use --instrument csv:FILE or prompt with real "
                                                                   r"actuators\)$"),
    ("measurement_failed", "the simulated instrument did not answer within 2 s",
     r"did not answer within 2 s: nothing was measured at posture 3; run the same command again to resume$"),
])
def test_the_services_instrument_says_what_to_do_when_it_cannot_measure(code, message, said) -> None:
    with pytest.raises(InstrumentError, match=said):
        ServiceInstrument(Refusing(code, message)).measure(2, "posture 3")  # type: ignore[arg-type]


def test_instrument_specs(nominal, tmp_path) -> None:
    with pytest.raises(ValueError, match="sim, csv:FILE or prompt"):
        open_instrument("theodolite", None, nominal)  # type: ignore[arg-type]
    assert isinstance(open_instrument("prompt", None, nominal), PromptInstrument)  # type: ignore[arg-type]


# -- the directory -------------------------------------------------------------------


def test_a_new_campaign_saves_its_plan_and_each_measurement(nominal, tmp_path) -> None:
    store = CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    assert len(store.postures) == 12 and store.measurements_taken == 0
    plan = json.loads((tmp_path / "c" / PLAN_FILE).read_text())
    assert plan["design"] == {"postures_per_leg": 2, "candidates": 100, "envelope_fraction": 1.0, "seed": 1}
    first = VALIDATION_STEPS["before"][0]
    store.add_validation(first, points_at(nominal, first.pose))
    with pytest.raises(ValueError, match="not the next"):
        store.add_validation(first, points_at(nominal, first.pose))
    posture = store.postures[0]
    store.add_posture(posture.leg, [400.0] * 6, points_at(nominal, posture.pose))
    with pytest.raises(ValueError, match="locks leg"):
        store.add_posture(6, [400.0] * 6, points_at(nominal, posture.pose))
    with pytest.raises(DirectoryError, match="in use by another campaign"):
        CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    store.close()

    resumed = CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    assert (resumed.measurements_taken, resumed.postures_measured) == (2, 1)
    assert resumed.postures == store.postures
    assert resumed.validation_steps_left("before")[0] == VALIDATION_STEPS["before"][1]
    saved = read_measurements(tmp_path / "c" / MEASUREMENTS_FILE, 3)
    assert list(saved.data.locked_leg) == [posture.leg] and not saved.problems
    assert "before,x_sweep,1," in (tmp_path / "c" / VALIDATION_FILE).read_text()


def test_a_directory_that_cannot_hold_this_campaign_is_refused(nominal, tmp_path) -> None:
    CampaignStore.open(tmp_path / "c", nominal, DESIGN).close()
    with pytest.raises(DirectoryError, match="planned with"):
        CampaignStore.open(tmp_path / "c", nominal, CampaignDesign(postures_per_leg=3, candidates=100, seed=1))
    other = nominal.model_copy(update={"name": "other", "zero_lengths": (1751.0,) * 6})
    with pytest.raises(DirectoryError, match="planned on geometry"):
        CampaignStore.open(tmp_path / "c", other, DESIGN)
    (tmp_path / "c" / "report").mkdir()
    (tmp_path / "c" / "report" / "index.html").write_text("done")
    with pytest.raises(DirectoryError, match="finished campaign"):
        CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / MEASUREMENTS_FILE).write_text("leg\n")
    with pytest.raises(DirectoryError, match="not a campaign's directory"):
        CampaignStore.open(tmp_path / "d", nominal, DESIGN)


def test_saved_rows_that_do_not_match_the_plan_are_refused(nominal, tmp_path) -> None:
    store = CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    posture = store.postures[0]
    store.add_posture(posture.leg, [400.0] * 6, points_at(nominal, posture.pose))
    store.close()
    path: Path = tmp_path / "c" / MEASUREMENTS_FILE
    path.write_text(path.read_text().replace(f"\n{posture.leg},", "\n6,"))
    with pytest.raises(CampaignError, match="does not match"):
        CampaignStore.open(tmp_path / "c", nominal, DESIGN)


def test_the_campaign_screens_its_measurements_as_calibrate_does(nominal, tmp_path) -> None:
    """An instrument file whose header names p1's columns p2 and p2's p1: on the symmetric
    target the distances are right, and only the nominal's readings tell. The campaign
    screened without the nominal's legs, so it skipped that check (and the unit checks)
    that `hexactl calibrate` makes on the very same file."""
    import io

    from hexactl.application.campaign.progress import Progress
    from hexactl.application.campaign.runner import _identify
    from hexactl.calibration.results import IdentificationOptions
    from hexactl.kinematics.inverse import leg_lengths, readings_from_lengths

    store = CampaignStore.open(tmp_path / "c", nominal, DESIGN)
    for posture in store.postures:
        absolute = absolute_from_relative(nominal.home, posture.pose)
        readings = readings_from_lengths(nominal.legs, np.array(leg_lengths(nominal.legs, absolute)))
        store.add_posture(posture.leg, readings, points_at(nominal, posture.pose)[[1, 0, 2]])
    with pytest.raises(CampaignError, match="the columns named p2 hold p1 and the columns named p1 hold p2"):
        _identify(store, IdentificationOptions(), Progress(io.StringIO()))
    store.close()
