"""``hexactl serve`` is two processes: if its API process dies, the service brings the
platform to rest, disables the actuators and exits with status 1."""

from __future__ import annotations

import os
import signal
from pathlib import Path

from hexactl.adapters.api.client import HexactlClient
from tools.serving import serve, spawned_children
from tests.api.test_service import WAIT_S, wait_for
from tests.reliability.support import enable


def test_the_service_stops_safely_when_its_api_process_dies(tmp_path: Path) -> None:
    with serve(tmp_path) as served:
        with HexactlClient(served.api, timeout_s=WAIT_S) as client:
            enable(client)
            client.call("move", pose=[0, 0, 30, 0, 0, 0], duration=5.0)  # under way when the API dies
        (api_pid,) = wait_for(lambda: spawned_children(served.process.pid), "the API process")
        os.kill(api_pid, signal.SIGKILL)
        assert served.wait(WAIT_S) == 1, served.log
    text = served.log
    for expected in ("the API process died (exit status -9): shutting down", "actuators disabled", "stopped"):
        assert expected in text, text
    assert "E-stop" not in text, text  # braked and disabled, not E-stopped
