"""Gross mis-sightings: ``full`` excludes them itself, in point and pose form (issue 14).

The campaigns are the paper's size (20 leg-lock postures per leg, 120 rows) with 4 rows each
holding one feature point moved 5–20 mm, two of them along the platform normal (the
scenario of tools/bench_outliers.py, which measures it over more seeds).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hexactl.calibration.campaign import CampaignDesign
from hexactl.calibration.identification import calibration_info, identify
from hexactl.calibration.results import IdentificationOptions, Method
from hexactl.sim.offline_campaign import OfflineCampaign, run_offline_campaign
from hexactl.sim.true_platform import true_geometry
from tools.bench_outliers import mis_sight, pose_form, position_error_mm

FULL = IdentificationOptions(method=Method.FULL)
NO_EXCLUSION = replace(FULL, exclusion_false_alarm=0.0)


@pytest.fixture(scope="module", params=[0, 1])
def scenario(request, nominal):
    seed = request.param
    true = true_geometry(nominal, seed=seed)
    campaign = run_offline_campaign(nominal, true, CampaignDesign(seed=seed))
    return true, campaign, *mis_sight(campaign, seed)


def _form(data, form, nominal):
    return pose_form(data, nominal) if form == "pose" else data


@pytest.mark.parametrize("form", ["points", "pose"])
def test_mis_sightings_are_excluded_and_the_accuracy_restored(nominal, scenario, form):
    true, campaign, corrupted, moved = scenario
    clean, bad = _form(campaign.data, form, nominal), _form(corrupted, form, nominal)
    baseline = position_error_mm(identify(clean, nominal, FULL), nominal, true)
    before = position_error_mm(identify(bad, nominal, NO_EXCLUSION), nominal, true)
    result = identify(bad, nominal)  # auto

    assert result.method is Method.FULL and "4 mis-sighted observation(s) excluded" in result.reason
    expected = {(line, point if form == "points" else 0) for line, point in moved}
    assert {(observation.line, observation.point) for observation in result.excluded} == expected
    # Pose form: a point moved along the normal tilts the fitted pose, spreading its offset.
    assert all(observation.residual_mm > 2.0 and observation.sigmas > 10.0 for observation in result.excluded)
    after = position_error_mm(result, nominal, true)
    assert after <= 1.5 * baseline and after < 0.6 * before, (baseline, before, after)
    assert result.chi2_per_dof < 1.3 and result.ok
    assert "excluded as gross mis-sightings" in result.warnings[0]
    info = calibration_info(result, "now", "", "nominal")
    assert all(f"line {line}:" in info.notes for line, _ in moved)


@pytest.mark.parametrize("form", ["points", "pose"])
def test_clean_data_exclude_nothing_and_give_the_same_parameters(nominal, scenario, form):
    _, campaign, _, _ = scenario
    data = _form(campaign.data, form, nominal)
    robust, plain = identify(data, nominal, FULL), identify(data, nominal, NO_EXCLUSION)
    assert robust.excluded == () and not any("mis-sighting" in warning for warning in robust.warnings)
    assert np.array_equal(robust.parameters.to_vector(), plain.parameters.to_vector())
    assert np.array_equal(robust.covariance, plain.covariance)


def test_only_the_mis_sighted_point_is_excluded_not_its_posture(nominal, leglock_campaign: OfflineCampaign):
    data = leglock_campaign.data
    points = np.array(data.points_mm)
    points[3, 1] += (12.0, -4.0, 6.0)
    corrupted = type(data)(data.locked_leg, data.readings_mm, data.lines, points_mm=points)
    result = identify(corrupted, nominal, FULL)
    assert [(observation.line, observation.point) for observation in result.excluded] == [(int(data.lines[3]), 2)]
    assert result.postures_used == len(data) and np.isfinite(result.residuals.normalised[3])


def test_calibrate_lists_the_excluded_observations(tmp_path, nominal, scenario, capsys):
    """Pose form: no distance screening, so all four mis-sightings reach ``full``."""
    from hexactl.adapters.cli.main import main
    from hexactl.adapters.files.geometry_file import load_geometry
    from hexactl.adapters.files.measurements import read_measurements, write_measurements

    from .conftest import NOMINAL_PATH

    _, _, corrupted, moved = scenario
    data = write_measurements(tmp_path / "data.csv", pose_form(corrupted, nominal))
    report, output = tmp_path / "report", tmp_path / "cal.toml"
    assert main(["calibrate", str(data), "--config", str(NOMINAL_PATH), "-o", str(output), "--report", str(report)]) == 0
    out = capsys.readouterr().out
    page = (report / "index.html").read_text(encoding="utf-8")
    notes = load_geometry(output).calibration.notes
    file_line = dict(zip(corrupted.lines, read_measurements(data, 3).data.lines))  # after the header, comments
    for row_line, _ in moved:
        line = file_line[row_line]
        assert f"excluded as a mis-sighting: line {line}: measured pose off by" in out
        assert f"excluded as a mis-sighting: line {line}: measured pose off by" in page
        assert f"excluded as a mis-sighting: line {line}: measured pose off by" in notes
