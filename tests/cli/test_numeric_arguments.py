"""Numeric options swept with what a slip or a script may give them (-1, 0, nan, inf,
1e308, 1e-300, a huge integer): each is meaningful and accepted, or refused at once by
argparse (exit 2, ``argument --X: …`` naming the range). Found by an outside review:
``calibrate --point-sigma 1e-200`` ended in numpy's traceback, ``--max-deviation -5``
wrote a calibration, ``simulate-campaign --point-sigma nan`` a file of NaN noise."""

from __future__ import annotations

import pytest

from hexactl.calibration.results import IdentificationOptions
from tests.cli.test_cli_robustness import NOBODY, exits_with, nothing_serves  # noqa: F401 - a fixture

CALIBRATE = ["calibrate", "never-read.csv", "-o", "never-written.toml"]
SIMULATE = ["simulate-campaign", "-o", "never-written.csv"]
PLAN = ["plan-leglock", "--leg", "1", "--count", "10"]
CAMPAIGN = ["campaign", "--out", "never-made", "--api", NOBODY]
SIM_ACTUATORS = ["sim-actuators", "--can", "virtual:never-opened", "--duration", "0.1"]  # short, were one taken
DEMO = ["demo", "--per-leg", "0"]  # refused after parsing, were the number taken: no demo runs
HUGE = "99999999999999999999999"
WAVE = ["wave", "--axis", "z:1", "--frequency", "1", "--cycles", "3", "--api", NOBODY]  # each case adds one option
RECORD = ["record", "run", "--duration", "1", "--api", NOBODY]

REFUSED = [
    # A noise (1σ) outside a nanometre to a metre: the identification's weights 1/σ²
    # overflowed (LinAlgError, OverflowError) or a negative one was squared away unseen.
    *[(CALIBRATE, "--point-sigma", value) for value in ("1e-200", "nan", "-1", "0", "inf", "1e308")],
    *[(CALIBRATE, "--reading-sigma", value) for value in ("0", "-1", "1e-300", "1e308")],
    *[(SIMULATE, "--point-sigma", value) for value in ("nan", "inf", "1e308", "1e-300", "-1")],
    # A bound on the deviation from nominal: a negative or NaN one was ignored, a tiny one
    # made leglock's bounds meet (scipy's ValueError).
    *[(CALIBRATE, "--max-deviation", value) for value in ("-5", "nan", "0", "1e-300", "inf")],
    # A negative seed: numpy's ValueError traceback.
    *[(command, "--seed", "-1") for command in (SIMULATE, PLAN, CAMPAIGN, DEMO, SIM_ACTUATORS)],
    *[(command, "--reset-faults", "-1") for command in (CAMPAIGN, DEMO)],
    # Candidates beyond memory: numpy's "Maximum allowed dimension exceeded" traceback.
    *[(command, "--candidates", value) for command in (PLAN, CAMPAIGN) for value in ("0", HUGE)],
    (PLAN, "--count", "0"), (SIMULATE, "--free", "-1"), (SIMULATE, "--per-leg", "-1"),
    # Waits beyond an hour: OverflowError and a "not JSON compliant" ValueError.
    *[(["status", "--api", NOBODY], "--timeout", value) for value in ("1e308", HUGE, "0", "nan")],
    # A telemetry period that overflowed: the publisher died, the service served on without it.
    *[(["serve", "--no-realtime"], "--telemetry-rate", value) for value in ("1e-300", "0.1", "nan")],
    *[(SIM_ACTUATORS, "--tick-ms", value) for value in ("1e308", "0", "nan")],  # 1e308: a traceback
    *[(SIM_ACTUATORS, option, value) for option in ("--drop-probability", "--corrupt-probability")
      for value in ("5", "-1", "nan")],
    *[(SIM_ACTUATORS, "--duration", value) for value in ("-1", "nan")],  # -1 stopped at once, nan never
    *[(["jog", "x=1", "--api", NOBODY], "--for", value) for value in ("1e308", "0", "nan")],
    # Beyond the bound the service states (1e308, 601, 51, …): refused only after connecting
    # (exit 1), naming the request's field (duration, frequency_hz, divisor), not the option.
    *[(["move", "x=1", "--api", NOBODY], "--duration", value) for value in ("1e308", "601", "nan")],
    *[(WAVE, "--frequency", value) for value in ("nan", "inf", "0", "-1", "1e308", "51")],
    *[(WAVE, "--cycles", value) for value in ("0", "1000001", HUGE)],
    *[(WAVE, "--axis", value) for value in ("z:1001", "roll:91", "yaw:1:361")],
    *[(RECORD, "--divisor", value) for value in ("0", "-1", "1e30", "10001", HUGE)],
    *[(RECORD, "--duration", value) for value in ("3601", "1e308", "nan")],
    *[(["frames", "--api", NOBODY], "--max-tilt", value) for value in ("90.5", "1e308", "0", "nan")],
    # A locked length or reading of nan was taken, and said to be outside the stroke.
    *[(PLAN, option, value) for option in ("--length", "--reading") for value in ("nan", "inf", "-inf")],
]


@pytest.mark.usefixtures("nothing_serves")
@pytest.mark.parametrize(("command", "option", "value"), REFUSED,
                         ids=[f"{command[0]} {option} {value}" for command, option, value in REFUSED])
def test_a_meaningless_number_is_refused_naming_the_option(command: list[str], option: str, value: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert exits_with([*command, option, value]) == 2
    error = capsys.readouterr().err
    assert f"argument {option}: " in error and "Traceback" not in error


@pytest.mark.parametrize("length", ["1e308", "-1e308", "1e30"])
def test_a_huge_locked_length_is_refused_in_a_line(length: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The reading it gives was printed to three decimals: 300 digits for 1e308."""
    assert exits_with([*PLAN, "--length", length]) == 2
    error = capsys.readouterr().err
    assert f"(a reading of {float(length):.6g} mm): leg 1 cannot be locked there" in error and len(error) < 200


def test_a_wave_ramp_beyond_half_its_cycles_is_refused_naming_the_option(capsys: pytest.CaptureFixture[str]) -> None:
    """The service refused it (exit 1) naming its request's ramp_cycles."""
    assert exits_with([*WAVE, "--ramp", "2"]) == 2
    assert "--ramp 2 ramps in and again out: at most half of cycles (3)" in capsys.readouterr().err


@pytest.mark.usefixtures("nothing_serves")
@pytest.mark.parametrize(("arguments", "says"), [
    (["status", "--api", NOBODY, "--timeout", "0"], "0 s: a client waits for the service more than 0 s and at most"),
    (["jog", "x=1", "--api", NOBODY, "--for", "0"], "0 s: jog for more than 0 s and at most 600 s"),
    ([*WAVE, "--cycles", "1e2"], "'1e2' is not written as a whole number: write 100"),
    # Found from outside: "write it in digits, 1000000000", which the next attempt was refused for
    ([*WAVE, "--cycles", "1e9"], "'1e9' is not a whole number from 1 to 1000000"),
    ([*WAVE, "--cycles", "nan"], "'nan' is not a whole number\n"),
    (["jog", "x=1", "--api", NOBODY, "--for", "1e400"], "'1e400' is not a finite number"),  # was "inf s: …", not as typed
    ([*WAVE, "--cycles", "2.5"], "'2.5' is not a whole number\n"),
    # Found from outside: "'3.0' is not a whole number", which it is, only not written as one
    (["leg-lock", "3.0", "--api", NOBODY], "'3.0' is not written as a whole number: write 3\n"),
])
def test_a_refused_number_is_told_what_it_may_be(arguments: list[str], says: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A time of 0 was "not a time from 0 to 3600 s", and 1e9 cycles "not a whole number"."""
    assert exits_with(arguments) == 2
    assert says in capsys.readouterr().err


@pytest.mark.usefixtures("nothing_serves")
@pytest.mark.parametrize("command", [CAMPAIGN, ["demo", "--out", "never-made"]], ids=["campaign", "demo"])
def test_a_campaign_too_small_to_identify_is_refused_before_anything_moves(command: list[str],
                                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Found from outside: ``campaign --per-leg 1`` drove and measured all six postures,
    then the identification refused 6 (at least 8), and the directory, planned for one per
    leg, could be neither finished nor grown."""
    assert exits_with([*command, "--per-leg", "1"]) == 2
    assert "--per-leg 1: 6 postures, and the identification needs at least 8: give --per-leg 2 or more" in \
        capsys.readouterr().err

def test_a_simulated_campaign_of_no_posture_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """It said "points_mm must have shape None, got (0,)"."""
    assert exits_with([*SIMULATE, "--per-leg", "0", "--free", "0"]) == 2
    assert "--per-leg 0 and --free 0: no posture to simulate" in capsys.readouterr().err


@pytest.mark.parametrize("velocity", ["x=0", "0,0,0,0,0,0", "-0,0,0,0,0,0", "x=99999", "0,0,0,0,0,-1e5"])
def test_a_jog_at_no_velocity_is_refused_before_asking_the_service(velocity: str,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """All zeros release a jog in the API: the service's release reply broke the command (TypeError).
    A component beyond the service's bound was refused only by it, after connecting (exit 1)."""
    assert exits_with(["jog", velocity, "--for", "1", "--api", NOBODY]) == 2
    assert "argument VELOCITY: " in capsys.readouterr().err


@pytest.mark.parametrize("setting", [{"point_sigma_mm": 1e-200}, {"reading_sigma_mm": 0.0},
                                     {"max_joint_deviation_mm": -5.0}, {"max_zero_length_deviation_mm": float("nan")}])
def test_the_library_refuses_the_same_settings_naming_them(setting: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=f"^{next(iter(setting))}: "):
        IdentificationOptions(**setting)
