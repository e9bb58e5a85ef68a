"""A command given an in-process bus (``memory:``, ``virtual:``) says that nothing in another
process can be on it: ``hexactl sim-actuators --can virtual:a`` in one terminal and
``hexactl serve --can virtual:a`` in another both ran, and never heard each other."""

from __future__ import annotations

import pytest

from hexactl.adapters.cli.main import main

NOTE = "is an in-process bus: only this process hears it, so nothing in another process"


def test_sim_actuators_on_an_in_process_bus_says_so(capsys) -> None:
    assert main(["sim-actuators", "--can", "virtual:in-process-note", "--duration", "0.05"]) == 0
    assert f"hexactl sim-actuators: --can virtual:in-process-note {NOTE}" in capsys.readouterr().err


@pytest.mark.parametrize("spec, noted", [("memory:rig", True), ("socketcan:vcan0", False)])
def test_serve_on_an_in_process_bus_says_so(monkeypatch, capsys, spec, noted) -> None:
    from hexactl.application import service

    monkeypatch.setattr(service, "run_service", lambda *arguments, **options: 0)  # not started: the note comes first
    assert main(["serve", "--can", spec, "--api", "tcp://127.0.0.1:1", "--telemetry", "tcp://127.0.0.1:2"]) == 0
    assert (f"hexactl serve: --can {spec} {NOTE}" in capsys.readouterr().err) is noted
