"""The telemetry rate is checked once, by one rule, before anything starts."""

from __future__ import annotations

import pytest

from hexactl.adapters.api.protocol import MAX_TELEMETRY_RATE_HZ
from hexactl.adapters.cli.main import main
from hexactl.application.service import ServiceConfig


@pytest.mark.parametrize("rate_hz", [0.0, -5.0, 1e-300, MAX_TELEMETRY_RATE_HZ * 2, float("nan")])
def test_a_service_config_refuses_a_rate_the_publisher_cannot_keep(rate_hz: float) -> None:
    with pytest.raises(ValueError, match=r"telemetry rate .* outside \[0.2, 1000\]: choose a rate"):
        ServiceConfig(telemetry_rate_hz=rate_hz)


def test_the_highest_rate_is_taken() -> None:
    assert ServiceConfig(telemetry_rate_hz=MAX_TELEMETRY_RATE_HZ).telemetry_rate_hz == MAX_TELEMETRY_RATE_HZ


def test_serve_refuses_the_rate_as_an_argument_before_starting(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["serve", "--telemetry-rate", "5000"])
    assert exit_.value.code == 2
    error = capsys.readouterr().err
    assert "argument --telemetry-rate: telemetry rate 5000 Hz outside [0.2, 1000]" in error
    assert "control loop" not in error
