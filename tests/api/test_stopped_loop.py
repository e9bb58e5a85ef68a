"""``hexactl serve`` with its control loop's process stopped (SIGSTOP; hung alike) while its
API process runs on: the API answers every request at once and says why. It used to send
each command into the loop's pipe regardless; after about 200 moves the pipe was full, the
worker waited on it, and ``status`` and ``estop`` went unanswered until the API's
watchdog ended the service two minutes later.

Now a command to a loop that has sent no report for a second is not sent
(``loop_silent``); an E-stop or a stop is queued all the same, and carried out once the
loop runs again.

The real command in a process of its own, on random loopback ports read from its log.
"""

from __future__ import annotations

import signal
from pathlib import Path

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.control.results import REPORT_SILENT_S
from tools.serving import HANG_S, serve, terminate, wait_until

MOVES = 300  # more than the ~200 that filled the pipe


def status(client: HexactlClient) -> dict:
    return client.call("status")["status"]


def enable(client: HexactlClient) -> None:
    def enabled() -> bool:
        reply = client.request("enable")
        return reply["ok"]

    wait_until(enabled, "the actuators to enable", HANG_S, poll_s=0.2)


def test_a_stopped_loop_gets_no_command_but_a_stop_and_the_api_answers_all_along(tmp_path: Path) -> None:
    with serve(tmp_path, "--no-realtime") as served, HexactlClient(served.api, timeout_s=HANG_S) as client:
        enable(client)
        served.process.send_signal(signal.SIGSTOP)  # the loop's process; the API's is its child
        try:
            wait_until(lambda: status(client)["loop"]["report_age_s"] > REPORT_SILENT_S, "the loop's silence seen",
                       HANG_S, seen=lambda: status(client)["loop"])
            codes = set()
            for index in range(MOVES):
                try:
                    client.call("move", pose=[0, 0, 1 + index / MOVES, 0, 0, 0], duration=1.0)
                except CommandError as error:
                    codes.add(error.code)
                    refusal = error
            assert codes == {"loop_silent"}, codes
            assert refusal.message.startswith("not sent: the control loop has sent no report for "), refusal
            assert "see status" in refusal.message

            reply = client.request("estop")
            assert not reply["ok"] and reply["error"]["code"] == "loop_silent", reply
            assert reply["error"]["message"].startswith("queued, to be carried out if the loop runs again"), reply
            assert status(client)["state"] == "enabled"  # the loop's last report: it has not run since
        finally:
            served.process.send_signal(signal.SIGCONT)
        wait_until(lambda: status(client)["state"] == "estop", "the queued E-stop carried out",
                   HANG_S, seen=lambda: status(client))
        # the loop reports again (how soon is the host's business: a wait, not a bound)
        wait_until(lambda: status(client)["loop"]["report_age_s"] <= REPORT_SILENT_S, "the loop reporting again",
                   HANG_S, seen=lambda: status(client)["loop"])
        client.call("reset")
        shutdown = terminate(served)
    assert shutdown.problems() == [], served.log
    assert served.log.count("loop move:") == 0, served.log  # none of the refused moves reached the loop
