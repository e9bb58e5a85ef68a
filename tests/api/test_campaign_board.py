"""What a client's campaign says (``progress``), as telemetry carries it to every display."""

from __future__ import annotations

from hexactl.adapters.api.campaign_board import SAID_CHARACTERS_KEPT, SENTENCES_KEPT, CampaignBoard
from hexactl.adapters.api.messages import ProgressRequest


def progress(done: int = 1, said: str | None = None) -> ProgressRequest:
    return ProgressRequest(v=1, id=1, cmd="progress", title="postures", done=done, total=20, said=said)


def test_the_latest_sentences_are_kept_in_order_and_aged() -> None:
    now = [100.0]
    board = CampaignBoard(clock=lambda: now[0])
    assert board.view() is None
    for n in range(SENTENCES_KEPT + 3):
        board.update(progress(done=1, said=f"sentence {n}"))
    now[0] += 2.5
    view = board.view()
    assert view["said"] == [f"sentence {n}" for n in range(3, SENTENCES_KEPT + 3)]
    assert view["title"] == "postures" and view["done"] == 1 and view["total"] == 20 and view["age_s"] == 2.5


def test_long_sentences_are_kept_within_a_size_that_every_telemetry_record_can_carry() -> None:
    board = CampaignBoard()
    for n in range(SENTENCES_KEPT):
        board.update(progress(said=f"{n:02d}" + "x" * 1998))  # the longest a request may say
    said = board.view()["said"]
    assert sum(map(len, said)) <= SAID_CHARACTERS_KEPT
    assert said[-1].startswith(f"{SENTENCES_KEPT - 1:02d}") and len(said[-1]) == 2000  # the newest, whole
    assert [s[:2] for s in said] == [f"{n:02d}" for n in range(SENTENCES_KEPT - len(said), SENTENCES_KEPT)]
    board.update(progress(said="short"))
    assert board.view()["said"][-2:] == [said[-1], "short"]
