"""The cue as the loop performs it: a shipped manoeuvre's plan streamed at its own rate into
the 500 Hz loop on ideal actuators, in simulated time (tools/simulated_stream.py), as
``hexactl cue`` streams it into a service."""

from __future__ import annotations

import numpy as np
import pytest

from hexactl.application.cueing import plan_cue
from hexactl.cueing.parameters import CueingParameters
from hexactl.cueing.washout import perceived_specific_force, rms_difference
from tools.simulated_stream import perform

TRACKING_COST_M_S2 = 0.1
"""How much worse than planned the performed cue may be, RMS m/s²: a tracker whose velocity
box was one worst-case fraction of every axis lagged the braking by 330 mm and added 0.24."""


@pytest.mark.parametrize("name", ["braking", "lane_change"])
def test_the_loop_performs_the_planned_cue_with_a_small_tracking_cost(nominal, vehicles, name: str) -> None:
    plan = plan_cue(vehicles[name], CueingParameters(), nominal)
    commanded, clamps = perform(plan.poses, plan.period_s, nominal)
    felt = perceived_specific_force(commanded, plan.period_s)
    performed = rms_difference(plan.vehicle_specific_force, felt)
    at_rest = rms_difference(plan.vehicle_specific_force, perceived_specific_force(np.zeros_like(commanded), plan.period_s))
    assert clamps == 0
    assert performed < at_rest  # the cue helps as performed, not only as planned
    assert performed <= plan.rms_error + TRACKING_COST_M_S2, (performed, plan.rms_error)
