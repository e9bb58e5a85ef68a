"""Wrong readings (a typo, a wrong column): ``full`` excludes a gross reading error as it does a
mis-sighting, names its line and leg, and the calibration is then the clean data's.

Campaigns: the small leg-lock campaign of conftest.py (10 postures per leg, 60 rows);
tools/bench_outliers.py measures the paper-size scenario (4 rows with a reading off by
5–60 mm) over more seeds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from hexactl.calibration import full
from hexactl.calibration.campaign import CampaignDesign, plan_campaign
from hexactl.calibration.data import MeasurementData
from hexactl.calibration.identification import calibration_info, identify
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, Method
from hexactl.sim.instrument import SimulatedInstrument
from hexactl.sim.offline_campaign import OfflineCampaign, execute_plans
from hexactl.sim.true_platform import true_geometry
from tools.bench_outliers import mis_sight, pose_form

FULL = IdentificationOptions(method=Method.FULL)


def _with_reading_off(data: MeasurementData, row: int, leg: int, offset_mm: float) -> MeasurementData:
    """``data`` with leg ``leg``'s (1–6) reading of ``row`` moved by ``offset_mm``."""
    readings = np.array(data.readings_mm)
    readings[row, leg - 1] += offset_mm
    return replace(data, readings_mm=readings)


def _within_uncertainty(result: IdentificationResult, reference: IdentificationResult, sigmas: float) -> bool:
    """Whether ``result``'s parameters are within ``sigmas`` standard deviations of ``reference``'s."""
    std = np.sqrt(np.diag(reference.covariance))
    return bool(np.max(np.abs(result.parameters.to_vector() - reference.parameters.to_vector()) / std) < sigmas)


@pytest.fixture(scope="module")
def clean_fits(nominal, leglock_campaign: OfflineCampaign) -> dict[str, tuple[MeasurementData, IdentificationResult]]:
    """Per form ("points", "pose"): the campaign's data and their ``full`` fit."""
    forms = {"points": leglock_campaign.data, "pose": pose_form(leglock_campaign.data, nominal)}
    return {form: (data, identify(data, nominal, FULL)) for form, data in forms.items()}


@pytest.mark.parametrize("form", ["points", "pose"])
@settings(max_examples=6, deadline=None)
@given(row=st.integers(0, 59), locked=st.booleans(), other_leg=st.integers(1, 5), size=st.floats(5.0, 60.0),
       sign=st.sampled_from([-1.0, 1.0]))
@example(row=39, locked=False, other_leg=1, size=5.0, sign=-1.0)  # the robust start once blamed the pose (pose form)
@example(row=34, locked=True, other_leg=1, size=7.0, sign=-1.0)  # ... and the posture's three points
def test_a_wrong_reading_is_excluded_and_named_with_its_line_and_leg(nominal, clean_fits, form, row, locked,
                                                                      other_leg, size, sign):
    data, clean = clean_fits[form]
    locked_leg = int(data.locked_leg[row])
    leg = locked_leg if locked else (locked_leg + other_leg - 1) % 6 + 1  # a free leg: any but the locked one
    line = int(data.lines[row])
    result = identify(_with_reading_off(data, row, leg, sign * size), nominal, FULL)

    assert [(observation.line, observation.point, observation.leg) for observation in result.excluded] == [(line, 0, leg)]
    (observation,) = result.excluded
    assert observation.kind == "reading error" and abs(observation.residual_mm - size) < 0.5
    assert str(observation).startswith(f"line {line}: leg {leg}'s reading off by")
    assert "reading(s) excluded as gross reading errors" in result.warnings[0]
    # It drops out as if never read: one degree of freedom less, its posture still tested and not flagged.
    assert result.degrees_of_freedom == clean.degrees_of_freedom - 1
    assert np.isfinite(result.residuals.normalised[row]) and line not in result.residuals.outlier_lines
    assert result.chi2_per_dof < 1.3 and _within_uncertainty(result, clean, 1.0)


def test_auto_keeps_full_and_names_the_reading_where_it_fell_back_to_leglock(nominal, leglock_campaign):
    """The issue: one typo made auto blame the platform and take leglock, 12× worse."""
    data = leglock_campaign.data
    row, leg = 3, int(leglock_campaign.data.locked_leg[3]) % 6 + 1  # a free leg of a leg-lock row
    result = identify(_with_reading_off(data, row, leg, 54.0), nominal)
    assert result.method is Method.FULL and "1 wrong reading(s) excluded" in result.reason
    assert [(observation.line, observation.leg) for observation in result.excluded] == [(int(data.lines[row]), leg)]
    notes = calibration_info(result, "now", "", "nominal").notes
    assert f"excluded as a reading error: line {int(data.lines[row])}: leg {leg}'s reading off by" in notes


@pytest.mark.parametrize("form", ["points", "pose"])
@pytest.mark.parametrize("seed", [20, 21, 22])
def test_clean_campaigns_exclude_nothing(nominal, leglock_campaign, form, seed):
    """Other platforms and noise on the same plans: nothing excluded, the plain fit's parameters."""
    true = true_geometry(nominal, seed=seed)
    plans = plan_campaign(nominal, CampaignDesign(postures_per_leg=10, free_postures=0, candidates=300, seed=11))
    campaign = execute_plans(nominal, true, plans, SimulatedInstrument.for_geometry(nominal, seed), 0.001, seed)
    data = campaign.data if form == "points" else pose_form(campaign.data, nominal)
    robust = identify(data, nominal, FULL)
    plain = identify(data, nominal, IdentificationOptions(method=Method.FULL, exclusion_false_alarm=0.0))
    assert robust.excluded == () and not any("gross" in warning for warning in robust.warnings)
    assert np.array_equal(robust.parameters.to_vector(), plain.parameters.to_vector())


@pytest.mark.parametrize("form", ["points", "pose"])
def test_a_mis_sighting_and_a_wrong_reading_in_one_campaign_are_both_found(nominal, leglock_campaign, clean_fits, form):
    data, moved = mis_sight(leglock_campaign, seed=3, rows=1)
    (sighted_line, point), = moved
    row = 40 if int(data.lines[40]) != sighted_line else 41
    leg = int(data.locked_leg[row]) % 6 + 1
    data = _with_reading_off(data, row, leg, -23.0)
    result = identify(pose_form(data, nominal) if form == "pose" else data, nominal, FULL)
    found = {(observation.line, observation.point, observation.leg) for observation in result.excluded}
    assert found == {(sighted_line, point if form == "points" else 0, 0), (int(data.lines[row]), 0, leg)}
    assert "excluded as gross mis-sightings and 1 reading(s) excluded as gross reading errors" in result.warnings[0]
    assert _within_uncertainty(result, clean_fits[form][1], 1.0)


def test_observations_a_gross_error_pushed_beyond_the_cut_come_back(nominal, leglock_campaign, monkeypatch):
    """A mis-sighted point biases the first fit enough to push good readings elsewhere beyond
    the cut; they are excluded in the first round, and come back once the point is out. (The
    robust start would exclude only the point: here it declines, as where it would touch too
    many postures, and the rounds start from the plain fit.)"""
    weights = []
    fit = full._fit
    monkeypatch.setattr(full, "_robust_start", lambda *arguments: None)

    def recording_fit(problem, *arguments):
        weights.append(problem.observation_weights(False))
        return fit(problem, *arguments)

    monkeypatch.setattr(full, "_fit", recording_fit)
    data, moved = mis_sight(leglock_campaign, seed=0, rows=1)
    result = full.identify_full(data, nominal, FULL)
    excluded_on_the_way = set(zip(*np.nonzero(np.min(weights, axis=0) == 0.0)))
    excluded_at_the_end = set(zip(*np.nonzero(weights[-1] == 0.0)))
    assert excluded_on_the_way - excluded_at_the_end  # some were excluded, then taken back
    assert [(observation.line, observation.point) for observation in result.excluded] == moved


def test_calibrate_lists_the_wrong_reading(tmp_path, nominal, leglock_campaign, capsys):
    from hexactl.adapters.cli.main import main
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.adapters.files.measurements import read_measurements, write_measurements

    from .conftest import NOMINAL_PATH

    data = leglock_campaign.data
    row, leg = 3, int(data.locked_leg[3]) % 6 + 1
    path = write_measurements(tmp_path / "data.csv", _with_reading_off(data, row, leg, 54.0))
    line = int(read_measurements(path, 3).data.lines[row])  # after the header and comments
    report, output = tmp_path / "report", tmp_path / "cal.toml"
    assert main(["calibrate", str(path), "--config", str(NOMINAL_PATH), "-o", str(output), "--report", str(report)]) == 0
    expected = f"excluded as a reading error: line {line}: leg {leg}'s reading off by"
    out = capsys.readouterr().out
    assert "method: auto chose full" in out and expected in out
    assert expected in (report / "index.html").read_text(encoding="utf-8").replace("&#x27;", "'")
    assert expected in load_geometry(output).calibration.notes
