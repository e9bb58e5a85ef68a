"""``PoseStream.send_paced``, the pace of ``hexactl cue``, on a clock of the test's own: each
pose goes when it is due, one a period from the first; one the host made late goes at once,
and does not delay those after it. Judged on the fake clock, so a busy host changes nothing."""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace

import pytest

from hexactl.adapters.api import stream_client
from hexactl.adapters.api.stream_client import PoseStream

PERIOD_S = 0.01


class Clock:
    """Monotonic time that moves only when slept on, or when the test says the host held
    the sender up."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        assert seconds >= 0.0
        self.now += seconds


class RecordedStream(PoseStream):
    """A stream that sends nowhere: when each pose was sent, on ``clock``; after the
    sends numbered in ``held_s`` (1 the first), the host holds the sender up that long."""

    def __init__(self, clock: Clock, held_s: dict[int, float]) -> None:
        super().__init__(client=None, source="paced test")  # type: ignore[arg-type]  # never opened
        self.clock, self.held_s = clock, held_s
        self.sent: list[tuple[float, Sequence[float]]] = []

    def send(self, pose: Sequence[float], sent_s: float | None = None) -> bool:
        self.sent.append((self.clock.now, pose))
        self.clock.now += self.held_s.get(len(self.sent), 0.0)
        return True


@pytest.fixture
def clock(monkeypatch) -> Clock:
    clock = Clock()
    monkeypatch.setattr(stream_client, "time", SimpleNamespace(monotonic=clock.monotonic, sleep=clock.sleep))
    return clock


def test_each_pose_goes_when_it_is_due(clock) -> None:
    poses = [[float(n), 0, 0, 0, 0, 0] for n in range(50)]
    stream = RecordedStream(clock, {})
    assert stream.send_paced(poses, PERIOD_S) == 0
    assert [pose for _, pose in stream.sent] == poses
    assert [t - 1000.0 for t, _ in stream.sent] == pytest.approx([n * PERIOD_S for n in range(50)], abs=1e-9)


def test_poses_made_late_go_at_once_and_the_rest_keep_their_deadlines(clock) -> None:
    stream = RecordedStream(clock, {3: 0.035})  # the host holds the sender 3.5 periods after the third
    stream.send_paced([[float(n), 0, 0, 0, 0, 0] for n in range(10)], PERIOD_S)
    sent = [round((t - 1000.0) / PERIOD_S, 6) for t, _ in stream.sent]
    assert sent == [0, 1, 2, 5.5, 5.5, 5.5, 6, 7, 8, 9]  # the three it was late with at once, then on time again
