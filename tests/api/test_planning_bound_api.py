"""The outside tester's request through the real server: ``play`` of a 10,000-waypoint
sequence file is refused at once (``invalid_sequence``, naming the count and the bound)
and never reaches the controller, let alone the loop."""

from __future__ import annotations

from hexactl.control.planning import MAX_WAYPOINTS
from tests.api.test_commands import send
from tests.control.test_planning_bound import tiny_toml


def test_play_of_the_10000_waypoint_file_is_refused_before_the_controller(service) -> None:
    (service.data_dir / "tiny10000.toml").write_text(tiny_toml(10_000))
    calls = len(service.controller.calls)
    reply = send(service, "play", sequence="tiny10000.toml")
    assert not reply["ok"] and reply["error"]["code"] == "invalid_sequence", reply
    message = reply["error"]["message"]
    assert "10000 waypoints" in message and f"split it into sequences of at most {MAX_WAYPOINTS} waypoints" in message
    assert len(service.controller.calls) == calls, service.controller.calls[calls:]


def test_play_of_a_file_at_the_bound_reaches_the_controller(service) -> None:
    (service.data_dir / "at_the_bound.toml").write_text(tiny_toml(MAX_WAYPOINTS))
    reply = send(service, "play", sequence="at_the_bound.toml")
    assert reply["ok"] and reply["waypoints"] == MAX_WAYPOINTS, reply
