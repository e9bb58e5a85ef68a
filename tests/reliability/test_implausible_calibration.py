"""Issue 10, finding 4, on the real two-process ``hexactl serve``: calibrations whose base
joints are 1 m off, platform joints 300 mm off, or whose zero posture moved, with zero
lengths chosen so that the set-points at the current pose are unchanged ("change 0.0 mm"),
were accepted while enabled and not checked at all while disabled; moves validated on
them then drove the simulated platform outside its envelope and joint cones. Each is now
refused with the parameter and bound named, enabled and disabled, and the active
calibration stays. The service then ends on SIGTERM as promised (:mod:`tools.serving`)."""

from __future__ import annotations

from pathlib import Path

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.files.geometry_file import geometry_to_toml
from hexactl.kinematics.geometry import Geometry
from tests.api.test_service import WAIT_S, status, wait_for
from tests.kinematics.calibrations import implausible_calibrations
from tests.reliability.support import recover
from tools.serving import serve, terminate

POSE = [100.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # away from the zero posture, where the finding's moves started


def refusals(client: HexactlClient, nominal: Geometry, state: str) -> None:
    """Each implausible calibration sent now is refused, naming its parameter and bound,
    and the active calibration stays."""
    active = status(client)["calibration_id"]
    for case, (calibration, parameter) in implausible_calibrations(nominal, POSE).items():
        reply = client.request("load_calibration", toml=geometry_to_toml(calibration))
        assert not reply["ok"], f"{case}, {state}: accepted"
        assert reply["error"]["code"] == "invalid_geometry", (case, state, reply)
        message = reply["error"]["message"]
        assert parameter in message and "from the nominal (bound" in message and "[limits] calibration_" in message, (
            case, state, message)
        assert status(client)["calibration_id"] == active, (case, state)


def test_each_implausible_calibration_is_refused_with_its_reason(tmp_path: Path, nominal: Geometry) -> None:
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=WAIT_S) as client:
            recover(client)
            client.call("move", pose=POSE)
            wait_for(lambda: status(client)["motion"] == "holding" and status(client)["pose_command"][0] > 99.9,
                     "the platform at x = 100 mm")
            refusals(client, nominal, "enabled")
            client.call("disable")
            wait_for(lambda: status(client)["state"] == "disabled", "the platform disabled")
            refusals(client, nominal, "disabled")
        shutdown = terminate(served)
    assert shutdown.problems() == [], f"{shutdown}\n{served.log}"
