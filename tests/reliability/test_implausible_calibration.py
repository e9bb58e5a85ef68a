"""Issue 10, finding 4, on the whole two-process service: calibrations whose base joints
are 1 m off, platform joints 300 mm off, or whose zero posture moved, with zero lengths
chosen so that the set-points at the current pose are unchanged ("change 0.0 mm"), were
accepted while enabled and not checked at all while disabled; moves validated on them
then drove the simulated platform outside its envelope and joint cones. Each is now
refused with the parameter and bound named, enabled and disabled, and the active
calibration stays."""

from __future__ import annotations

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.geometry_file import geometry_to_toml
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import status, wait_for
from tests.kinematics.calibrations import implausible_calibrations
from tests.reliability.support import recover

POSE = [100.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # away from the zero posture, where the finding's moves started


@pytest.mark.parametrize("enabled", [True, False], ids=["enabled", "disabled"])
def test_each_implausible_calibration_is_refused_with_its_reason(client: HexactlClient, nominal: Geometry,
                                                                 enabled: bool) -> None:
    recover(client)
    client.call("move", pose=POSE)
    wait_for(lambda: status(client)["motion"] == "holding", "the platform at x = 100 mm")
    if not enabled:
        client.call("disable")
        wait_for(lambda: status(client)["state"] == "disabled", "the platform disabled")
    active = status(client)["calibration_id"]
    for case, (calibration, parameter) in implausible_calibrations(nominal, POSE).items():
        reply = client.request("load_calibration", toml=geometry_to_toml(calibration))
        assert not reply["ok"], f"{case}: accepted"
        assert reply["error"]["code"] == "invalid_geometry", case
        message = reply["error"]["message"]
        assert parameter in message and "from the nominal (bound" in message and "[limits] calibration_" in message, (
            case, message)
        assert status(client)["calibration_id"] == active, case
    recover(client)
    client.call("move", pose=[0.0] * 6)
    wait_for(lambda: status(client)["motion"] == "holding", "the platform home")
