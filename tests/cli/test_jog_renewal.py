"""``hexactl jog``'s renewals against a service whose answers are scripted: what ends the
command, and what a held button rides through (a stall of this machine or the service)."""

from __future__ import annotations

from typing import Any

import pytest

from hexactl.adapters.cli.jog_commands import _in_cli_terms, _pace, _renew
from hexactl.control.results import jog_ended_message

FIELDS = {"velocity": [0.0, 0.0, 5.0, 0.0, 0.0, 0.0], "frame": "zero"}


class ScriptedService:
    """Answers each ``jog`` request with the next of ``replies`` (then ok for jog 7), and
    records what it was sent."""

    def __init__(self, *replies: dict[str, Any]) -> None:
        self.replies = list(replies)
        self.sent: list[dict[str, Any]] = []

    def request(self, cmd: str, /, **fields: Any) -> dict[str, Any]:
        assert cmd == "jog"
        self.sent.append(fields)
        return self.replies.pop(0) if self.replies else {"ok": True, "jog": 7}


def _refused(code: str, **details: Any) -> dict[str, Any]:
    return {"ok": False, "error": {"code": code, "message": f"{code} (scripted)", "details": details}}


def test_a_renewal_held_up_past_its_deadline_does_not_end_the_jog() -> None:
    """Found on a loaded host: one renewal answered ``expired`` (not carried out: it reached
    the loop 234 ms after its deadline) ended ``hexactl jog`` with exit 1, the operator's
    jog cut short by the machine's load. The next renewal goes on with the same jog."""
    service = ScriptedService({"ok": True, "jog": 7}, _refused("expired"))
    assert _renew(service, FIELDS, 7, for_s=0.05, every_s=0.005) is None
    assert len(service.sent) > 3
    assert all(fields.get("renews") == 7 for fields in service.sent)


def test_a_lapsed_jog_starts_again_and_a_stopped_one_ends_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    lapsed = ScriptedService(_refused("jog_ended", lapsed=True, reason="the deadman lapsed"), {"ok": True, "jog": 9})
    assert _renew(lapsed, FIELDS, 7, for_s=0.03, every_s=0.005) is None
    # a new jog in place of the lapsed one (refused if a stop came after the lapse), then renewed as such
    assert lapsed.sent[1] == {**FIELDS, "restarts": 7} and lapsed.sent[2]["renews"] == 9
    # and said: the platform braked to rest between them (found from outside: nothing was)
    assert capsys.readouterr().err == ("hexactl jog: jog 7 lapsed (this machine or the service held up its renewals): "
                                       "the platform braked; jogging on as jog 9\n")

    stop_after_lapse = _refused("jog_ended", lapsed=False, reason="stopped")
    restart_refused = ScriptedService(_refused("jog_ended", lapsed=True, reason="the deadman lapsed"), stop_after_lapse)
    assert _renew(restart_refused, FIELDS, 7, for_s=1.0, every_s=0.005) == stop_after_lapse
    assert len(restart_refused.sent) == 2

    stop = _refused("jog_ended", lapsed=False, reason="stopped")
    stopped = ScriptedService(stop)
    assert _renew(stopped, FIELDS, 7, for_s=1.0, every_s=0.005) == stop
    assert len(stopped.sent) == 1


def test_a_renewal_cancelled_by_a_stop_ends_the_command_with_the_jogs_own_word() -> None:
    """Found from outside: a stop from another terminal while a renewal was queued ended the
    command with "jog cancelled, not carried out", said of a jog that had run 1.5 s."""
    stop = _refused("jog_ended", lapsed=False, reason="stopped")
    service = ScriptedService(_refused("cancelled"), stop)
    assert _renew(service, FIELDS, 7, for_s=1.0, every_s=0.005) == stop
    assert [fields.get("renews") for fields in service.sent] == [7, 7]
    # Found from outside: the renewal sent again at once was cancelled too, taken with the stop
    twice = ScriptedService(_refused("cancelled"), _refused("cancelled"), stop)
    assert _renew(twice, FIELDS, 7, for_s=1.0, every_s=0.005) == stop and len(twice.sent) == 3
    # said in this command's terms, not the API's ("send jog without renews")
    for reason in ("stopped", "the deadman lapsed (no renewal in time)"):  # the loop's words too (found from outside)
        refused = {"ok": False, "error": {"code": "jog_ended", "message": jog_ended_message(7, reason)}}
        assert _in_cli_terms(refused)["error"]["message"] == f"jog 7 has ended ({reason}): run hexactl jog again to jog on"


@pytest.mark.parametrize(("speed", "said"), [(0.5, "50%"), (0.0996, "10%"), (2 / 600, "0.33%"), (0.025, "2.5%"),
                                             (1e-7, "under 0.01%")])
def test_a_jogs_pace_is_said_in_two_digits_below_ten_percent(speed: float, said: str) -> None:
    """A jog at 2 mm/s of 600 was said to run at "0% of the motion limits"."""
    assert _pace(speed) == f"at the velocity asked ({said} of the motion limits)"
