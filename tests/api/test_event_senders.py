"""Who did it, through the real service (two processes, the API and the loop): each client
names itself (``X-Client``), the service adds where it connected from, and the loop's
events in telemetry say which client sent the command behind each, an E-stop's fault too
(outside review: the E-stop's event said ``estop command``, and nothing said whose)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hexactl.adapters.api.client import HexactlClient
from hexactl.application.service import Service, ServiceConfig
from tests.api.support import service_here
from tests.api.test_service import WAIT_S, status, wait_for
from tests.reliability.support import recover, tolerating_loop_stalls

ANN, BOB = "ann at the bench", "bob in the control room"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    directory = tmp_path_factory.mktemp("senders")
    with service_here(ServiceConfig(api_endpoint="tcp://127.0.0.1:*", telemetry_endpoint="tcp://127.0.0.1:*",
                                    data_dirs=(directory,))) as service:
        yield service


def events_after(client: HexactlClient, t: float) -> list[tuple[str, str | None]]:
    return [(event["code"], event["sender"]) for event in status(client)["events"] if event["t"] > t]


def newest_t(client: HexactlClient) -> float:
    events = status(client)["events"]
    return events[-1]["t"] if events else 0.0


def test_the_events_name_the_client_behind_each_command_and_the_estop_its_presser(service) -> None:
    with HexactlClient(service.api_endpoint, timeout_s=WAIT_S, name=ANN) as ann, \
            HexactlClient(service.api_endpoint, timeout_s=WAIT_S, name=BOB) as bob:

        def scenario() -> None:
            recover(ann)
            since = newest_t(ann)
            ann.call("move", pose=[0, 0, 30, 0, 0, 0], duration=20.0)
            wait_for(lambda: status(bob)["motion"] == "moving", "the move under way")
            bob.call("stop")
            wait_for(lambda: status(ann)["motion"] == "holding", "braked to rest")
            bob.call("estop")
            wait_for(lambda: status(ann)["state"] == "estop", "the E-stop latched")
            record = status(ann)
            assert [fault["message"] for fault in record["faults"]] == [f"estop command from {BOB} (127.0.0.1)"]
            ann.call("reset")
            wait_for(lambda: ("reset", f"{ANN} (127.0.0.1)") in events_after(ann, since), "the reset's event")
            assert events_after(ann, since) == [("move", f"{ANN} (127.0.0.1)"), ("stop", f"{BOB} (127.0.0.1)"),
                                                ("estop", f"{BOB} (127.0.0.1)"), ("reset", f"{ANN} (127.0.0.1)")]

        tolerating_loop_stalls(scenario, lambda: service.controller)
