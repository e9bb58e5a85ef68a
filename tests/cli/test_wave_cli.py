"""``hexactl wave``'s arguments and the wave in ``status`` and the monitor (issue 12); the
command against a running service: tests/reliability/test_waves.py."""

from __future__ import annotations

import argparse

import pytest

from hexactl.adapters.cli.common import CliError
from hexactl.adapters.cli.main import build_parser
from hexactl.adapters.cli.telemetry_text import format_telemetry
from hexactl.adapters.cli.wave_commands import axis_argument, wave_fields
from tests.cli.test_monitor import RECORD, rendered


def test_the_arguments_make_the_request() -> None:
    arguments = build_parser().parse_args(["wave", "--axis", "z:2", "--axis", "roll:0.5:90", "--frequency", "1.5",
                                           "--cycles", "6", "--ramp", "2", "--frame", "tool"])
    assert wave_fields(arguments) == {"axes": {"z": {"amplitude": 2.0}, "roll": {"amplitude": 0.5, "phase_deg": 90.0}},
                                      "frequency_hz": 1.5, "cycles": 6, "ramp_cycles": 2.0, "frame": "tool"}
    plain = build_parser().parse_args(["wave", "--axis", "x:-1", "--frequency", "1", "--cycles", "2"])
    assert wave_fields(plain) == {"axes": {"x": {"amplitude": -1.0}}, "frequency_hz": 1.0, "cycles": 2}


@pytest.mark.parametrize("text, fragment", [
    ("w:1", "AXIS one of x, y, z, roll, pitch, yaw"), ("z", "AXIS:AMPLITUDE[:PHASE]"), ("z:1:2:3", "AXIS:AMPLITUDE"),
    ("z:two", "the amplitude and the phase are numbers"),
    # not a traceback from the client's JSON encoder, as "z:nan" gave
    ("z:nan", "finite numbers"), ("roll:1:inf", "finite numbers"), ("z:-infinity", "finite numbers"),
])
def test_a_bad_axis_says_what_to_give(text, fragment) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=fragment.replace("[", r"\[").replace("]", r"\]")):
        axis_argument(text)


def test_an_axis_twice_and_validate_with_wait_are_refused(capsys) -> None:
    twice = build_parser().parse_args(["wave", "--axis", "z:1", "--axis", "z:2", "--frequency", "1", "--cycles", "2"])
    with pytest.raises(CliError, match="--axis z is given twice"):
        wave_fields(twice)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["wave", "--axis", "z:1", "--frequency", "1", "--cycles", "2", "--validate", "--wait"])
    assert "not allowed with argument" in capsys.readouterr().err


def test_status_and_the_monitor_show_the_wave() -> None:
    assert "wave         none" in rendered(RECORD)
    playing = {**RECORD, "wave": {"cycle": 2, "cycles": 5, "phase": "steady"}}
    ended = {**RECORD, "wave": {"cycle": 3, "cycles": 5, "phase": "aborted"}}
    for show in (rendered, format_telemetry):
        assert "cycle 2 of 5 (steady)" in show(playing)
        assert "aborted in cycle 3 of 5" in show(ended)
