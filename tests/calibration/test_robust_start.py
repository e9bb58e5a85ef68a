"""Gross errors that defeat plain least squares: ``full``'s robust start finds them.

Plain least squares lets gross errors bias the fit they are tested against. Found from
outside on the campaign ``hexactl simulate-campaign --seed 1`` writes (120 rows): feature
point p1 sighted 20 mm high in every 11th row pushed good observations of 95 postures beyond
the cut, so exclusion gave up and a biased calibration was written; one reading typed 300 mm
off made ``auto`` blame the sensors and take ``leglock``; a coordinate with its decimal point
slipped (metres off) kept the fit from converging at all. tools/bench_outliers.py measures
such scenarios over more seeds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hexactl.calibration import full
from hexactl.calibration.campaign import CampaignDesign
from hexactl.calibration.identification import identify
from hexactl.calibration.results import IdentificationOptions, IdentificationResult, Method
from hexactl.sim.offline_campaign import OfflineCampaign, run_offline_campaign
from hexactl.sim.true_platform import true_geometry
from tools.bench_outliers import pose_form

FULL = IdentificationOptions(method=Method.FULL)


@pytest.fixture(scope="module")
def campaign(nominal) -> OfflineCampaign:
    return run_offline_campaign(nominal, true_geometry(nominal, 1), CampaignDesign(seed=1))


@pytest.fixture(scope="module")
def clean(nominal, campaign) -> dict[str, IdentificationResult]:
    """The clean data's fit per form ("points", "pose")."""
    return {"points": identify(campaign.data, nominal, FULL),
            "pose": identify(pose_form(campaign.data, nominal), nominal, FULL)}


def _close_to(result: IdentificationResult, reference: IdentificationResult, sigmas: float) -> bool:
    std = np.sqrt(np.diag(reference.covariance))
    return bool(np.max(np.abs(result.parameters.to_vector() - reference.parameters.to_vector()) / std) < sigmas)


def _in_form(data, form, nominal):
    return pose_form(data, nominal) if form == "pose" else data


@pytest.mark.parametrize("form", ["points", "pose"])
def test_a_point_sighted_20_mm_high_in_every_11th_posture_is_excluded_there(nominal, campaign, clean, form):
    data = campaign.data
    points = np.array(data.points_mm)
    rows = np.arange(10, len(data), 11)  # 11 of 120 postures
    points[rows, 0, 2] += 20.0
    result = identify(_in_form(replace(data, points_mm=points), form, nominal), nominal, FULL)

    listed = {(observation.line, observation.point) for observation in result.excluded}
    assert listed == {(int(data.lines[row]), 1 if form == "points" else 0) for row in rows}
    assert result.ok and result.chi2_per_dof < 1.3
    assert _close_to(result, clean[form], 3.0)


@pytest.mark.parametrize("form", ["points", "pose"])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_coordinate_ten_times_too_large_is_excluded_and_the_fit_converges(nominal, campaign, clean, form, axis):
    data = campaign.data
    row, point = 22, 1
    points = np.array(data.points_mm)
    points[row, point, axis] *= 10.0  # the decimal point slipped: metres off
    result = identify(_in_form(replace(data, points_mm=points), form, nominal), nominal, FULL)

    assert result.ok  # converged and determined
    # Pose form: the row's pose, not its six readings, which its pose could follow as well.
    assert [(observation.line, observation.point, observation.leg) for observation in result.excluded] == [
        (int(data.lines[row]), 2 if form == "points" else 0, 0)]
    assert _close_to(result, clean[form], 3.0)


def test_a_reading_300_mm_off_is_excluded_and_auto_keeps_full(nominal, campaign, clean):
    data = campaign.data
    row, leg = 8, 3
    assert data.locked_leg[row] != leg  # a free leg
    readings = np.array(data.readings_mm)
    readings[row, leg - 1] += 300.0
    result = identify(replace(data, readings_mm=readings), nominal)  # auto

    assert result.method is Method.FULL and "1 wrong reading(s) excluded" in result.reason
    assert [(observation.line, observation.leg) for observation in result.excluded] == [(int(data.lines[row]), leg)]
    assert _close_to(result, clean["points"], 3.0)


def test_the_robust_start_declines_a_model_error_spread_over_the_campaign(nominal, leglock_campaign):
    """Sliding sensors (every free reading disturbed): beyond the cut in most postures, so
    nothing is excluded and full says the model does not fit."""
    data = leglock_campaign.data
    readings = np.array(data.readings_mm)
    free = data.locked_leg[:, None] != np.arange(1, 7)[None, :]
    readings[free] += np.random.default_rng(0).normal(0.0, 3.0, np.count_nonzero(free))
    result = full.identify_full(replace(data, readings_mm=readings), nominal, FULL)
    assert not result.excluded and "too many for isolated mis-sightings" in " ".join(result.warnings)


def test_observations_left_out_that_would_unpin_a_posture_stay_in(nominal, campaign):
    """Two searches for gross errors can each exclude a different explanation of one posture's
    misfit (its three points, or two of its readings); fitting both models on the union of
    what they left out would leave that posture's pose unpinned (a singular pose block: a
    traceback). That posture keeps its observations; the others are left out."""
    data = campaign.data
    left_out = {(5, point, 0) for point in (1, 2, 3)} | {(5, 0, 1), (5, 0, 2), (9, 2, 0)}
    result = full.identify_full(data, nominal, FULL, left_out=left_out)
    assert result.ok
    assert [(observation.row, observation.point, observation.leg) for observation in result.excluded] == [(9, 2, 0)]
