"""A campaign that does not keep its calibration (no ``--apply``, or no improvement)
returns the controller to the geometry it was planned on, even when the service was
restarted after the calibration was loaded (its undo history then starts empty, and
rolling back was refused ``no_previous_calibration``: the campaign could not finish, run
again or not, and left the calibration in force and kept for the next restart)."""

from __future__ import annotations

import io
from pathlib import Path
from types import SimpleNamespace

import pytest

from hexactl.adapters.api.client import CommandError
from hexactl.adapters.files.geometry_file import geometry_id, parse_geometry
from hexactl.application.campaign.driver import PlatformDriver
from hexactl.application.campaign.progress import Progress
from hexactl.application.campaign.runner import _conclude

CALIBRATED = "d64930c558dd5cfe"


class Calibrations:
    """A controller at rest with its calibration undo history: ``history`` before the
    active one, as the service keeps it (empty after a restart)."""

    def __init__(self, history: list[str], active: str) -> None:
        self.history, self.active, self.sent, self.polls = history, active, [], 0
        self.sources: list[object] = []

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "rollback_calibration":
            self.sent.append(cmd)
            if not self.history:
                raise CommandError("no_previous_calibration", f"there is no earlier calibration to roll back to: "
                                   f"none is kept before {self.active}")
            self.active = self.history.pop()
            return {}
        if cmd == "load_calibration":
            self.sent.append(cmd)
            self.history.append(self.active)
            self.active = geometry_id(parse_geometry(str(fields["toml"]), "request"))
            self.sources.append(fields.get("source"))
            return {}
        self.polls += 1
        record = {"state": "enabled", "motion": "holding", "sequence": None, "leg_feedback": [400.0] * 6,
                  "loop": {"report_age_s": 0.002},
                  "t": 0.1 * self.polls, "faults": [], "locked_leg": None, "calibration_id": self.active}
        return {"status": record}


@pytest.mark.parametrize(("history", "sent"), [
    (["nominal"], ["rollback_calibration"]),  # the load undone: the history as it was before
    ([], ["rollback_calibration", "load_calibration"]),  # the service restarted since the load
    (["nominal", CALIBRATED], ["rollback_calibration", "load_calibration"]),  # another client loaded one since
])
def test_a_calibration_not_kept_leaves_the_planned_geometry_active(nominal, history, sent) -> None:
    planned = geometry_id(nominal)
    history = [planned if entry == "nominal" else entry for entry in history]
    controller = Calibrations(history, "0123456789abcdef" if len(history) == 2 else CALIBRATED)
    out = io.StringIO()
    # a folder named with a line end: sent escaped, as the service's one-line rule for a source wants
    store = SimpleNamespace(geometry=nominal, path=lambda name: Path("/data/camp\naign") / name)
    _conclude(PlatformDriver(controller), store, better=True, apply=False,  # type: ignore[arg-type]
              progress=Progress(out, io.StringIO()))
    assert controller.active == planned and controller.sent == sent
    # a load says what it loads: the service records it as the calibration's source
    assert controller.sources == ["hexactl campaign: the geometry /data/camp\\naign/campaign.json was planned on"] * (
        "load_calibration" in sent)
    assert "rolled back to the geometry the campaign started on (--apply keeps it)" in out.getvalue()
