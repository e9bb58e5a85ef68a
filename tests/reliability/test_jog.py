"""Jog on the whole service, watched by the independent bus monitor: into a soft limit it
comes to rest on it with no refusal and no guard clamp; when its client stops renewing
(or goes away) it brakes to rest by itself (issue 12)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from hexactl.adapters.api.client import CommandError, HexactlClient
from hexactl.adapters.cli.main import main
from tests.api.test_service import status, wait_for
from tests.reliability.support import recover, tolerating_loop_stalls

RENEW_S = 0.05
SOFT_X_MM = 8.0


@contextmanager
def _renewing(endpoint: str, velocity: list[float]) -> Iterator[list[str]]:
    """Renew the jog every RENEW_S from a client and a thread of its own while the block
    runs (what a held button does); yields the codes of the refusals met. A ``jog_ended``
    (this process stalled past the deadman, so the jog was braking) is answered as a client
    should: the next renewal starts it again. An ``expired`` (a renewal held up past its
    deadline on a loaded host) was not carried out: the next goes on as usual."""
    refusals: list[str] = []
    done = threading.Event()

    def renew() -> None:
        with HexactlClient(endpoint, timeout_s=5.0) as own:
            while not done.is_set():
                try:
                    own.call("jog", velocity=velocity)
                except CommandError as error:
                    refusals.append(error.code)
                done.wait(RENEW_S)

    thread = threading.Thread(target=renew, name="renewing")
    thread.start()
    try:
        yield refusals
    finally:
        done.set()
        thread.join()


def test_a_jog_into_a_soft_limit_rests_on_it_and_a_lapsed_one_brakes(client: HexactlClient, service, capsys) -> None:
    def scenario() -> None:
        recover(client)
        client.call("move", pose=[0, 0, 0, 0, 0, 0], duration=1.0)
        wait_for(lambda: status(client)["motion"] == "holding", "the zero posture")
        client.call("set_frames", soft_limits={"upper": [SOFT_X_MM, None, None, None, None, None]})
        clamps = status(client)["loop"]["guard_clamps"]
        with _renewing(service.api_endpoint, [20, 0, 0, 0, 0, 0]) as refusals:  # 8 mm at 20 mm/s
            at_limit = wait_for(lambda: (s := status(client))["jog"] and s["jog"]["phase"] == "at_end" and s,
                                "the jog at rest on the soft limit")
            assert at_limit["jog"]["end"] == f"the soft limit on x at {SOFT_X_MM:g} mm"
            assert at_limit["pose_command"][0] == pytest.approx(SOFT_X_MM, abs=1e-5)
            assert at_limit["loop"]["guard_clamps"] == clamps
            assert main(["status", "--api", service.api_endpoint]) == 0
            shown = capsys.readouterr().out
            assert "jog " in shown and f"x 20 mm/s in zero, to the soft limit on x at {SOFT_X_MM:g}" in shown
        assert set(refusals) <= {"jog_ended", "expired"}, refusals
        # No more renewals: the deadman lapses and the jog ends by itself.
        wait_for(lambda: status(client)["jog"] is None, "the jog to end")
        # Back the other way, then the client goes away mid-motion: it brakes to rest.
        with HexactlClient(service.api_endpoint, timeout_s=5.0) as leaving:
            leaving.call("jog", velocity=[-20, 0, 0, 0, 0, 0])
            wait_for(lambda: status(client)["motion"] == "moving", "the jog to start")
        ended = wait_for(lambda: (s := status(client))["jog"] is None and s["motion"] == "holding" and s,
                         "the lapsed jog to brake to rest")
        assert -20 < ended["pose_command"][0] < SOFT_X_MM  # it did not run on to a limit
        assert ended["last_jog"]["reason"] == "the deadman lapsed (no renewal in time)"
        assert ended["loop"]["guard_clamps"] == clamps
        assert client.call("status")["status"]["state"] == "enabled"

    try:
        tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))
    finally:
        client.call("clear_frames")


def test_the_jog_command_line_jogs_for_a_while_and_releases(client: HexactlClient, service, capsys) -> None:
    def scenario() -> None:
        recover(client)
        client.call("move", pose=[0, 0, 0, 0, 0, 0], duration=1.0)
        wait_for(lambda: status(client)["motion"] == "holding", "the zero posture")
        exit_code = main(["jog", "z=10", "--for", "1", "--api", service.api_endpoint])
        out = capsys.readouterr().out
        assert exit_code == 0, out
        assert "jogging (jog " in out and "released; at rest at" in out
        limit_z = service.controller.config.motion.max_velocity[2]
        assert f"at the velocity asked ({1000 / limit_z:.2g}% of the motion limits)" in out  # 10 mm/s asked: 2.5 %
        final = status(client)
        top = client.call("geometry")["geometry"]["limits"]["pose_max"][2]
        # Up, and released short of the limit it heads for; how far past 10 mm the release's
        # latency takes it is a benchmark (tools/bench_jog_cli.py), not this test's business.
        assert final["jog"] is None and final["motion"] == "holding" and 0.0 < final["pose_command"][2] < top

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))


def test_a_stop_from_another_client_ends_the_jog_command(client: HexactlClient, service, capsys) -> None:
    """Found from outside: ``hexactl jog`` re-sent its jog after another terminal's
    ``hexactl stop``, which started a new jog 50 ms later and ran its full time; only an
    E-stop ended it. Its renewals now name the jog, and a stop ends the command: exit 1,
    saying who stopped it."""

    def scenario() -> None:
        recover(client)
        client.call("move", pose=[0, 0, 0, 0, 0, 0], duration=1.0)
        wait_for(lambda: status(client)["motion"] == "holding", "the zero posture")
        codes: list[int] = []
        jogging = threading.Thread(target=lambda: codes.append(main(["jog", "x=-5", "--for", "60", "--api",
                                                                      service.api_endpoint])))
        jogging.start()
        try:
            wait_for(lambda: (status(client)["jog"] or {}).get("phase") == "jogging", "the jog to start")
            client.call("stop")
        finally:
            jogging.join(timeout=120)
        assert not jogging.is_alive() and codes == [1], codes
        err = capsys.readouterr().err
        assert "has ended (stopped): run hexactl jog again to jog on" in err, err
        assert "the service recorded since it started: " in err and "stop: any motion under way brakes to rest" in err
        rested = wait_for(lambda: (s := status(client))["motion"] == "holding" and s, "the platform at rest")
        assert rested["jog"] is None
        assert [event["code"] for event in rested["events"]].count("jog_started") >= 1
        started = [event for event in rested["events"] if event["code"] == "jog_started"]
        stop_t = max(event["t"] for event in rested["events"] if event["code"] == "stop")
        assert all(event["t"] < stop_t for event in started), rested["events"]  # none started after the stop

    tolerating_loop_stalls(scenario, lambda: service.controller, cleanup=lambda: recover(client))


def test_a_bad_jog_is_refused_with_what_to_do(client: HexactlClient, service, capsys) -> None:
    with pytest.raises(CommandError) as short:
        client.call("jog", velocity=[1, 2, 3])
    assert short.value.code == "invalid_request" and "velocity" in str(short.value)
    with pytest.raises(SystemExit) as typed:
        main(["jog", "x=nan", "--for", "1", "--api", service.api_endpoint])
    assert typed.value.code == 2 and "velocity 'x=nan': velocity x is not a finite number" in capsys.readouterr().err
