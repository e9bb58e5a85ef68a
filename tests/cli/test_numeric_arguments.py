"""Numeric options swept with what a slip or a script may give them (-1, 0, nan, inf,
1e308, 1e-300, a huge integer): each is meaningful and accepted, or refused at once by
argparse (exit 2, ``argument --X: …`` naming the range). Found by an outside review:
``calibrate --point-sigma 1e-200`` ended in numpy's traceback, ``--max-deviation -5``
wrote a calibration, ``simulate-campaign --point-sigma nan`` a file of NaN noise."""

from __future__ import annotations

import pytest

from hexactl.calibration.results import IdentificationOptions
from tests.cli.test_cli_robustness import exits_with

CALIBRATE = ["calibrate", "never-read.csv", "-o", "never-written.toml"]
SIMULATE = ["simulate-campaign", "-o", "never-written.csv"]

REFUSED = [
    # A noise (1σ) outside a nanometre to a metre: the identification's weights 1/σ²
    # overflowed (LinAlgError, OverflowError) or a negative one was squared away unseen.
    *[(CALIBRATE, "--point-sigma", value) for value in ("1e-200", "nan", "-1", "0", "inf", "1e308")],
    *[(CALIBRATE, "--reading-sigma", value) for value in ("0", "-1", "1e-300", "1e308")],
    *[(SIMULATE, "--point-sigma", value) for value in ("nan", "inf", "1e308", "1e-300", "-1")],
    # A bound on the deviation from nominal: a negative or NaN one was ignored, a tiny one
    # made leglock's bounds meet (scipy's ValueError).
    *[(CALIBRATE, "--max-deviation", value) for value in ("-5", "nan", "0", "1e-300", "inf")],
]


@pytest.mark.parametrize(("command", "option", "value"), REFUSED)
def test_a_meaningless_number_is_refused_naming_the_option(command: list[str], option: str, value: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert exits_with([*command, option, value]) == 2
    error = capsys.readouterr().err
    assert f"argument {option}: " in error and "Traceback" not in error


@pytest.mark.parametrize("setting", [{"point_sigma_mm": 1e-200}, {"reading_sigma_mm": 0.0},
                                     {"max_joint_deviation_mm": -5.0}, {"max_zero_length_deviation_mm": float("nan")}])
def test_the_library_refuses_the_same_settings_naming_them(setting: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=f"^{next(iter(setting))}: "):
        IdentificationOptions(**setting)
