"""A campaign's move that comes to rest short of its goal is never measured there: cut
short by someone (a ``stop``, another client's move), it ends the campaign naming who,
as the measurement would have been the wrong posture or waypoint (a test-motion waypoint
so measured showed a stop's distance as the platform's error, before or after
calibration); braked by the service itself when its API fell silent (a loaded host), it
is sent again."""

from __future__ import annotations

import pytest

from hexactl.application.campaign.driver import MOVE_ATTEMPTS, CampaignError, PlatformDriver

SILENT = [("command_link_silent", "nothing from the API for 1.0 s: the motion is braked to rest", None),
          ("command_link_heard", "the API is heard again after 1.2 s of silence", None)]
STOPPED = [("stop", "any motion under way brakes to rest", "dashboard, browser 10.0.0.7 (127.0.0.1)")]
REPLACED = [("move", "4.1 s as planned", "hexactl ann@bench-2 (127.0.0.1)")]


class Platform:
    """A controller whose moves end on their goal, except the next ones ``cuts`` names:
    those come to rest halfway, after the events (code, message, sender) listed for them."""

    def __init__(self, *cuts: list[tuple[str, str, str | None]]) -> None:
        self.cuts, self.pose, self.events, self.moves, self.polls = list(cuts), [0.0] * 6, [], 0, 0

    def _event(self, code: str, message: str, sender: str | None) -> None:
        self.events.append({"seq": len(self.events) + 1, "t": 0.0, "code": code, "message": message, "sender": sender})

    def call(self, cmd: str, **fields: object) -> dict:
        if cmd == "move":
            goal = list(fields["pose"])  # type: ignore[call-overload]
            self.moves += 1
            self._event("move", "1.0 s as planned", "hexactl campaign")
            cut = self.cuts.pop(0) if self.cuts else []
            for event in cut:
                self._event(*event)
            self.pose = [value / 2 for value in goal] if cut else goal
            return {"duration": 0.0, "goal": goal}
        if cmd == "events":
            return {"events": [event for event in self.events if event["seq"] > fields.get("after", 0)]}
        self.polls += 1
        record = {"state": "enabled", "motion": "holding", "sequence": None, "leg_feedback": [400.0] * 6,
                  "loop": {"report_age_s": 0.002},
                  "t": 0.1 * self.polls, "faults": [], "pose_command": self.pose, "events": self.events[-8:]}
        return {"status": record}


GOAL = [100.0, 0.0, 0.0, 0.0, 5.0, 0.0]


@pytest.mark.parametrize(("cut", "said"), [
    (STOPPED, r"stop: any motion under way brakes to rest, sent by dashboard, browser 10\.0\.0\.7"),
    (REPLACED, r"move: 4\.1 s as planned, sent by hexactl ann@bench-2"),
    (SILENT + STOPPED, r"command_link_silent: .*; stop: .*sent by dashboard"),
    (STOPPED * 9, r"stop: any motion under way brakes to rest, sent by dashboard"),  # more than a record carries
])
def test_a_move_someone_cut_short_ends_the_campaign_naming_who(cut, said) -> None:
    platform = Platform(cut)
    with pytest.raises(CampaignError, match=rf"move to \[100\.0, .*stopped short of its goal, at \[50\.0, .*{said}.*"
                                            "Nothing was measured there; run the same command again"):
        PlatformDriver(platform).move(GOAL)  # type: ignore[arg-type]
    assert platform.moves == 1


def test_a_move_the_service_braked_when_its_api_fell_silent_is_sent_again() -> None:
    platform = Platform(SILENT)
    assert PlatformDriver(platform).move(GOAL)["pose_command"] == GOAL  # type: ignore[arg-type]
    assert platform.moves == 2
    hopeless = Platform(*[SILENT] * MOVE_ATTEMPTS)
    with pytest.raises(CampaignError, match="braked it when its API fell silent"):
        PlatformDriver(hopeless).move(GOAL)  # type: ignore[arg-type]
    assert hopeless.moves == MOVE_ATTEMPTS
