"""The wave commands through the real API server (a fake controller behind it): the
request becomes the controller's WaveSpec, malformed waves are invalid requests naming
the field, the replies carry the figures or the refusal (issue 12)."""

from __future__ import annotations

import pytest

from hexactl.control.frames import Frame
from hexactl.control.waves import WaveSpec
from tests.api.test_commands import send

WAVE = {"axes": {"z": {"amplitude": 2}, "roll": {"amplitude": 0.5, "phase_deg": 90}}, "frequency_hz": 1.5,
        "cycles": 6}


def test_a_wave_request_is_the_controllers_wave_spec(service) -> None:
    service.controller.state = "enabled"
    reply = send(service, "wave", frame="tool", ramp_cycles=2, **WAVE)
    assert reply["message"] == "waving" and reply["duration"] == 4.0 and reply["samples"] == 3000
    assert reply["peak_leg_speed_leg"] == 2 and reply["peak_pose_velocity"][2] == 12.5
    name, (spec,) = service.controller.calls[-1]
    assert name == "wave" and type(spec) is WaveSpec
    assert spec == WaveSpec(frame=Frame.TOOL, ramp_cycles=2.0, **WAVE)


def test_validate_wave_says_valid_with_the_figures_or_the_refusal(service) -> None:
    valid = send(service, "validate_wave", **WAVE)
    assert valid["valid"] and valid["refusal"] is None and valid["wave"]["duration"] == 4.0
    refused = send(service, "validate_wave", **{**WAVE, "axes": {"z": {"amplitude": 200}}})
    assert not refused["valid"] and refused["wave"] is None
    assert refused["refusal"]["code"] == "planning_failed" and refused["refusal"]["details"]["kind"] == "leg_speed"


def test_a_refused_wave_keeps_the_controllers_code(service) -> None:
    reply = send(service, "wave", **WAVE)
    assert reply["error"]["code"] == "not_enabled"


@pytest.mark.parametrize("fields, fragment", [
    ({"axes": {"z": {"amplitude": "2"}}}, "amplitude"),
    ({"axes": {"w": {"amplitude": 2}}}, "axes"),
    ({"axes": {}}, "axes"),
    ({"cycles": 2.5}, "cycles"),
    ({"frequency_hz": 0}, "frequency_hz"),
    ({"ramp_cycles": 4}, "at most half of cycles"),
    ({"shape": "square"}, "shape"),
    ({"frame": "platform"}, "frame"),
    ({"speed": 1}, "speed"),
])
def test_a_malformed_wave_is_an_invalid_request_naming_the_field(service, fields, fragment) -> None:
    reply = send(service, "wave", **{**WAVE, **fields})
    assert reply["error"]["code"] == "invalid_request" and fragment in reply["error"]["message"]
    assert not service.controller.calls
