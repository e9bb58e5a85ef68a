"""The link to the actuators in telemetry and ``status`` (``link``: bus state, send failures,
the link's note), as the operator sees it in ``hexactl status``: a CAN bus going
error-passive is said before it goes bus-off, a silent leg is named, failed sends are
counted. A controller and six firmwares on one ``memory:`` bus, stepped in simulated time."""

from __future__ import annotations

import can
import pytest

from hexactl.adapters.api.messages import Telemetry
from hexactl.adapters.api.wire import jsonable
from hexactl.adapters.cli.telemetry_text import format_telemetry
from hexactl.control.local_controller import LocalController
from hexactl.control.telemetry import LinkTelemetry
from hexactl.adapters.can.transport import open_bus
from tests.reliability.test_other_controller import Bench

CAN_ERR_CRTL = 0x004  # SocketCAN error class: controller problems (data[1] says which)
CAN_ERR_CRTL_RX_PASSIVE = 0x10


@pytest.fixture
def bench(nominal):
    bench = Bench(nominal)
    yield bench
    bench.close()


def record(controller: LocalController) -> dict:
    """The telemetry record as the API publishes it, checked against its model."""
    return Telemetry.model_validate(jsonable(controller.telemetry())).model_dump(mode="json")


def link_row(text: str) -> str:
    (row,) = [line for line in text.splitlines() if line.lower().startswith("link ")]
    return row


def test_a_healthy_link_reads_active_with_no_failures_in_telemetry_status_and_text(bench: Bench) -> None:
    controller = bench.controller()
    bench.run(100)
    assert controller.telemetry().link == LinkTelemetry("active", 0, "")
    assert controller.status().details["link"] == {"bus_state": "active", "send_failures": 0, "detail": ""}
    assert link_row(format_telemetry(record(controller))) == "link           CAN bus active; no send failures"


def test_an_error_passive_bus_is_said_in_capitals_with_what_to_check(bench: Bench) -> None:
    controller = bench.controller()
    bench.run(10)
    with open_bus(bench.channel) as interface:  # the kernel's error frame, as SocketCAN delivers it
        interface.send(can.Message(arbitration_id=CAN_ERR_CRTL, data=bytes((0, CAN_ERR_CRTL_RX_PASSIVE, 0, 0, 0, 0, 0, 0)),
                                   is_error_frame=True, is_extended_id=False))
    bench.run(2)
    shown = record(controller)
    assert shown["link"]["bus_state"] == "passive"
    row = link_row(format_telemetry(shown))
    assert row.startswith("LINK           CAN bus ERROR-PASSIVE") and "terminations" in row


def test_a_silent_leg_is_named_in_the_links_note(bench: Bench) -> None:
    controller = bench.controller()
    bench.run(10)
    bench.actuators.firmwares[3].inject.silent = True  # leg 4 stops transmitting
    bench.run(200)  # 0.4 s: past the link's silence threshold
    link = controller.telemetry().link
    assert link is not None and link.bus_state == "active" and link.detail.startswith("silent legs: 4")
    assert "silent legs: 4" in link_row(format_telemetry(record(controller)))


def test_failed_sends_are_counted(bench: Bench) -> None:
    controller = bench.controller()
    bench.run(10)
    link = controller.hardware
    bus_send = link._bus.send

    def refuse(message, timeout=None):
        raise can.CanOperationError("Failed to transmit: No buffer space available")

    link._bus.send = refuse
    bench.run(3)
    link._bus.send = bus_send
    bench.run(1)
    failures = controller.telemetry().link.send_failures
    assert failures >= 3
    assert f"; {failures} send failures" in link_row(format_telemetry(record(controller)))
