"""Two ``hexactl serve --can socketcan:vcan0`` on one bus, as a second one started by mistake
from another shell would be, beside ``hexactl sim-actuators``: the enabled one latches FAULT
``other_controller`` as the second starts and E-stops the actuators, which the second sees
reported and latches too, so its ``enable`` is refused; the first's own E-stop works; once
the second has ended and 1 s has passed, ``reset`` and ``enable`` work again. Real SocketCAN, where each process's socket hears the
other's frames and not its own. Collected only where vcan0 exists (tests/conftest.py);
elsewhere tests/test_vcan_in_uml.py runs it inside user-mode Linux, with the guest's settings
of tests/vcan/test_service_over_vcan.py."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S
from tests.vcan.test_service_over_vcan import (
    WAIT_S,
    enabled_at_rest,
    running_service,
    simulated_actuators,
    status,
    wait_status,
)

pytestmark = pytest.mark.vcan


def test_a_second_service_on_the_bus_is_refused_and_faults_the_first(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "first").mkdir()
    (tmp_path / "second").mkdir()
    with simulated_actuators(), running_service(tmp_path / "first") as first_served, \
            HexactlClient(first_served.api, timeout_s=WAIT_S) as first:
        enabled_at_rest(first)
        assert status(first)["other_controller"] is None
        monkeypatch.chdir(tmp_path / "second")  # a service in the first's working directory is refused earlier
        with running_service(tmp_path / "second") as second_served, \
                HexactlClient(second_served.api, timeout_s=WAIT_S) as second:
            faulted = wait_status(first, lambda r: r["state"] != "enabled", "the first to hear the second")
            assert faulted["state"] == "estop", faulted
            assert [fault["code"] for fault in faulted["faults"]] == ["other_controller", "estop"], faulted["faults"]
            assert "another controller's" in faulted["faults"][0]["message"]
            wait_status(second, lambda r: r["state"] == "estop", "the second to latch the actuators' E-stop")
            with pytest.raises(CommandError) as refused:
                second.call("enable")
            assert refused.value.code == "latched", refused.value
            wait_status(second, lambda r: (r["other_controller"] or {}).get("age_s", 1e9) < OTHER_CONTROLLER_WINDOW_S,
                        "the second hearing the first within the window")  # a wait: a busy host may stall either
            first.call("estop")
            wait_status(first, lambda r: r["state"] == "estop" and all(leg["state"] == "estop" for leg in r["legs"]),
                        "the first's E-stop, with the second on the bus")
            second_served.process.send_signal(signal.SIGTERM)
            assert second_served.process.wait(WAIT_S) == 0, second_served.final_text()
        wait_status(first, lambda r: r["other_controller"]["age_s"] > OTHER_CONTROLLER_WINDOW_S,
                    "the second silent for the window")
        first.call("reset")
        enabled_at_rest(first)  # waits for the actuators to leave their E-stop
        first.call("disable")
        first_served.process.send_signal(signal.SIGTERM)
        assert first_served.process.wait(WAIT_S) == 0, first_served.final_text()
