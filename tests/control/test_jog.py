"""Jog with a deadman, in simulated time: it runs only while renewed, brakes to rest
jerk-limited when the renewals stop, and comes to rest on a soft or hard limit with no
refusal and no guard clamp (issue 12)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexactl.control.config import ControllerConfig
from hexactl.control.frames import Frame, OperatorFrames
from hexactl.control.results import DEADMAN_LAPSED, CommandResult, ErrorCode
from hexactl.control.submitter import commands_from
from hexactl.kinematics.frames import apply, transform_of
from hexactl.kinematics.soft_limits import SoftLimits
from hexactl.kinematics.workspace import Violation, ViolationKind, assess_poses

RENEW_CYCLES = 25  # 50 ms at 500 Hz: well inside the 0.2 s deadman
X_AT_MOST_5 = OperatorFrames(soft_limits=SoftLimits(upper=(5, None, None, None, None, None)))


def _hold(rig, velocity, cycles: int, frame: Frame = Frame.ZERO) -> list:
    """Renew the jog every RENEW_CYCLES for ``cycles``; every reply."""
    replies = []
    for _ in range(0, cycles, RENEW_CYCLES):
        replies.append(rig.controller.jog(velocity, frame))
        rig.run(RENEW_CYCLES)
    return replies


def _commanded(rig, cycles: int) -> np.ndarray:
    """(cycles, 6) commanded poses (mm, rad) of the next ``cycles`` cycles."""
    poses = []
    for _ in range(cycles):
        rig.run()
        poses.append(rig.controller.snapshot.pose_command)
    return np.array(poses)


def test_a_jog_into_a_soft_limit_comes_to_rest_on_it_with_no_refusal_and_no_clamp(rig) -> None:
    assert rig.controller.set_frames(X_AT_MOST_5).ok
    rig.enabled()
    replies = _hold(rig, [10, 0, 0, 0, 0, 0], 1500)
    assert all(reply.ok for reply in replies), [r.message for r in replies if not r.ok]
    assert replies[0].details["to_limit"] and replies[0].details["end"] == "the soft limit on x at 5 mm"
    s = rig.controller.snapshot
    assert s.jog is not None and s.jog.phase.value == "at_end" and s.motion.value == "holding"
    assert s.pose_command[0] == pytest.approx(5.0, abs=1e-5) and s.pose_command[0] <= 5.0  # on it, to 10 nm
    assert s.clamped_cycles == 0
    rig.assert_setpoints_safe()
    # From on the limit, a new jog has nowhere to go, at the pace asked (it said 1: the limits)
    rig.controller.jog([0] * 6)
    rig.settle()
    again = rig.controller.jog([10, 0, 0, 0, 0, 0])
    assert again.ok and again.details["speed"] == replies[0].details["speed"] < 1.0, again


def test_a_jog_into_the_hardware_limit_comes_to_rest_on_it(rig, geometry) -> None:
    rig.enabled()
    replies = _hold(rig, [0, 0, 40, 0, 0, 0], 5000)
    assert all(reply.ok for reply in replies)
    s = rig.controller.snapshot
    assert s.jog is not None and s.jog.phase.value == "at_end" and s.jog.to_limit
    z = s.pose_command[2]
    (here,) = assess_poses(geometry, [[*s.pose_command[:3], *np.degrees(s.pose_command[3:])]])
    (beyond,) = assess_poses(geometry, [[0, 0, z + 1e-3, 0, 0, 0]])
    assert not here.violations and beyond.violations  # on the boundary: a micrometre on is outside
    assert s.clamped_cycles == 0
    rig.assert_setpoints_safe()


def test_a_jog_whose_deadman_lapses_brakes_to_rest_jerk_limited(rig) -> None:
    rig.enabled()
    _hold(rig, [20, 0, 0, 0, 0, 0], 500)  # 1 s: at its cruise speed
    assert rig.controller.snapshot.jog.phase.value == "jogging"
    poses = _commanded(rig, 400)  # no renewal: it lapses within 0.2 s and brakes
    s = rig.controller.snapshot
    assert s.jog is None and s.last_jog.reason == DEADMAN_LAPSED and s.motion.value == "holding"
    period = rig.period_ns / 1e9
    velocity = np.diff(poses[:, 0]) / period
    acceleration = np.diff(velocity) / period
    limits = rig.controller.config.motion
    assert velocity[0] == pytest.approx(20.0, rel=1e-6)  # was cruising when the deadman lapsed
    assert np.all(velocity >= -1e-9)  # braked along its path: never backwards
    assert np.max(np.abs(acceleration)) <= limits.max_acceleration[0] * (1 + 1e-6)
    assert np.max(np.abs(np.diff(acceleration) / period)) <= limits.max_jerk[0] * (1 + 1e-6)
    assert s.pose_command[0] < 100  # short of where the plan was heading
    assert np.all(poses[-50:, 0] == poses[-1, 0])


def test_the_deadman_interval_is_configurable(make_rig) -> None:
    rig = make_rig(config=ControllerConfig(jog_deadman_s=0.5)).enabled()
    assert rig.controller.jog([5, 0, 0, 0, 0, 0]).details["deadman_s"] == 0.5
    rig.run(200)  # 0.4 s: still jogging
    assert rig.controller.snapshot.jog.phase.value == "jogging"
    rig.run(60)
    assert rig.controller.snapshot.jog.phase.value == "braking"


def test_a_release_brakes_and_ends_the_jog_said_as_released_by_whom(rig) -> None:
    """Found from outside: a release was carried out as a stop, recorded ``stop`` and the
    jog ``stopped``, so an operator's own release could not be told from another's stop."""
    rig.enabled()
    number = _hold(rig, [10, 0, 0, 0, 0, 0], 250)[0].details["jog"]
    with commands_from("hexactl ann@bench-2"):
        released = rig.controller.jog([0, 0, 0, 0, 0, 0])
    assert released.ok
    rig.settle()
    assert rig.controller.outcome(released.details["ticket"]).message == f"jog {number} released: braking to rest"
    assert rig.controller.snapshot.last_jog.reason == "released"
    events = [(e.code, e.message, e.sender) for e in rig.controller.snapshot.events[-2:]]
    assert events == [("jog_released", f"jog {number} released: braking to rest", "hexactl ann@bench-2"),
                      ("jog_ended", f"jog {number}: released", None)]
    again = rig.controller.jog([0] * 6)
    rig.run()
    assert rig.controller.outcome(again.details["ticket"]).message == "nothing to release: no jog is under way"


def test_a_release_brakes_only_a_jog_not_the_move_that_took_it_over(rig) -> None:
    """A release that reaches the loop after another client's move replaced the jog leaves
    that move alone (it used to stop whatever moved)."""
    rig.enabled()
    rig.controller.jog([10, 0, 0, 0, 0, 0])
    rig.run(50)
    assert rig.controller.move([0, 0, 20, 0, 0, 0], relative=True).ok
    rig.run()
    assert rig.controller.jog([0] * 6).ok  # the page's release, late
    rig.settle()
    assert rig.controller.snapshot.pose_command[2] == pytest.approx(20.0, abs=1e-6)  # the move went to its goal


def test_a_release_reaches_the_loop_even_before_the_snapshot_shows_the_jog(rig, monkeypatch) -> None:
    """Found from outside: hexactl jog's final release found only the previous jog, braking,
    in the facade's snapshot, answered "nothing to release", and the jog just restarted ran
    until its deadman lapsed. The loop decides, and says what it did: the reply, from the
    facade's snapshot, said "nothing to release" while the loop braked the jog."""
    rig.enabled()
    before = rig.controller.snapshot  # no jog in it
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.run(20)
    monkeypatch.setattr(rig.controller._jogs, "_snapshot", lambda: before)
    released = rig.controller.jog([0] * 6)
    rig.run()
    assert rig.controller.snapshot.jog.phase.value == "braking"
    assert rig.controller.snapshot.jog.reason == "released"
    assert rig.controller.outcome(released.details["ticket"]).message == f"jog {number} released: braking to rest"


def test_a_new_velocity_replans_the_jog_under_way(rig) -> None:
    rig.enabled()
    first = _hold(rig, [10, 0, 0, 0, 0, 0], 250)[0]
    turned = rig.controller.jog([0, 10, 0, 0, 0, 0])
    assert turned.ok and turned.details["jog"] != first.details["jog"]
    _hold(rig, [0, 10, 0, 0, 0, 0], 500)
    s = rig.controller.snapshot
    assert s.jog.velocity == (0.0, 10.0, 0.0, 0.0, 0.0, 0.0) and s.pose_command[1] > 4.0
    assert s.clamped_cycles == 0


def test_a_jog_about_the_tool_point_keeps_it_put(rig) -> None:
    frames = OperatorFrames(work=(0, 0, 300, 0, 0, 0), tool=(0, 0, 300, 0, 0, 0))
    assert rig.controller.set_frames(frames).ok
    rig.enabled()

    def tool_point():
        s = rig.controller.snapshot
        absolute = np.asarray(s.active.home) + np.asarray(s.pose_command)
        return np.array(apply(transform_of(absolute), frames.frames(s.active.home).tool.translation))

    before, drift = tool_point(), []
    for _ in range(20):
        assert rig.controller.jog([0, 0, 0, 2, 0, 0], Frame.TOOL).ok
        for _ in range(RENEW_CYCLES):
            rig.run()
            drift.append(np.linalg.norm(tool_point() - before))
    assert np.degrees(rig.controller.snapshot.pose_command[3]) > 0.5  # it turned
    assert max(drift) < 1e-3


def test_a_jog_is_refused_when_it_cannot_run(rig) -> None:
    bad = rig.controller.jog([1, 0, 0, 0, 0, float("nan")])
    assert bad.error.value == "invalid_argument" and "finite" in bad.message
    assert rig.controller.jog([1, 0, 0]).error.value == "invalid_argument"
    assert rig.controller.jog([1, 0, 0, 0, 0, 0]).error.value == "not_enabled"
    rig.enabled()
    assert rig.controller.leg_lock(2).ok
    rig.run(2)
    locked = rig.controller.jog([1, 0, 0, 0, 0, 0])
    assert locked.error.value == "leg_locked" and "unlock first" in locked.message


@pytest.mark.parametrize("tiny", [1e-320, 5e-324, 1e-7])
def test_a_velocity_too_slow_to_move_is_refused_naming_the_floor_not_an_internal_error(rig, tiny: float) -> None:
    """Found from outside: a subnormal component (1e-320 mm/s) made the planner's step
    overflow to infinity and the jog fail with internal_error; 1e-6 on an axis still jogs,
    and a tiny component beside a real one is no problem."""
    rig.enabled()
    for axis in (0, 5):
        velocity = [0.0] * 6
        velocity[axis] = tiny
        refused = rig.controller.jog(velocity)
        assert refused.error == "invalid_argument" and "too slow to move: at least 1e-06" in refused.message, refused
    assert rig.controller.jog([tiny, 0, 0, 0, 0, 1e-6]).ok
    rig.controller.jog([0] * 6)
    rig.settle()
    assert rig.controller.jog([10, tiny, 0, 0, 0, 0]).ok
    beyond = rig.controller.jog([10000.0001, 0, 0, 0, 0, 0])
    assert beyond.message.startswith("a jog velocity component of 10000.0001 is beyond 10000"), beyond.message


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(direction=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda d: np.linalg.norm(d) > 0.2),
       bound=st.floats(2.0, 20.0))
def test_a_jog_in_any_direction_ends_inside_every_limit_and_on_one(make_rig, direction, bound) -> None:
    """Property: a soft-limit box around the start; wherever the jog heads, it ends inside
    the box and on its surface."""
    rig = make_rig()
    box = OperatorFrames(soft_limits=SoftLimits(lower=(-bound,) * 3 + (None,) * 3, upper=(bound,) * 3 + (None,) * 3))
    assert rig.controller.set_frames(box).ok
    rig.enabled()
    velocity = [30 * d for d in direction] + [0, 0, 0]
    replies = _hold(rig, velocity, 2500)
    assert all(reply.ok for reply in replies)
    position = np.array(rig.controller.snapshot.pose_command[:3])
    assert np.all(np.abs(position) <= bound + 1e-9)
    assert np.max(np.abs(position)) == pytest.approx(bound, abs=1e-5)
    assert rig.controller.snapshot.clamped_cycles == 0


def test_a_jog_renewed_past_its_horizon_goes_on_without_slowing(rig) -> None:
    """No limit within the horizon: renewals re-plan it before it is reached, and the
    platform cruises on at the jog's speed."""
    from hexactl.control.jog_planning import JOG_HORIZON_S

    rig.enabled()
    first = rig.controller.jog([5, 0, 0, 0, 0, 0])
    assert first.ok and not first.details["to_limit"]
    positions = []
    for _ in range(round(2.5 * JOG_HORIZON_S * 500 / RENEW_CYCLES)):
        assert rig.controller.jog([5, 0, 0, 0, 0, 0]).ok
        for _ in range(RENEW_CYCLES):
            rig.run()
            positions.append(rig.controller.snapshot.pose_command[0])
    velocity = np.diff(positions) * 500
    assert np.all(velocity[500:] == pytest.approx(5.0, rel=1e-6))  # past the ramp-up: never slower
    assert positions[-1] > 2.0 * JOG_HORIZON_S * 5.0


def test_a_jog_keeps_its_number_and_one_event_however_long_it_is_held(rig) -> None:
    """Found from outside: each re-plan before the horizon was a new jog, with a new number
    and a jog_started event every 2.6 s; a jog held for 600 s wrote 230 of them and pushed
    who started it out of the loop's events."""
    from hexactl.control.jog_planning import JOG_HORIZON_S

    rig.enabled()
    first = rig.controller.jog([5, 0, 0, 0, 0, 0])
    number = first.details["jog"]
    for _ in range(round(3 * JOG_HORIZON_S * 500 / RENEW_CYCLES)):
        renewed = rig.controller.jog([5, 0, 0, 0, 0, 0], renews=number)
        assert renewed.ok and renewed.details["jog"] == number, renewed
        rig.run(RENEW_CYCLES)
    assert rig.controller.snapshot.jog.jog == number
    assert [event.code for event in rig.controller.snapshot.events].count("jog_started") == 1


def test_a_stop_ends_a_held_jog_for_good(rig) -> None:
    """Found from outside: another client's stop braked the jog, and the next renewal of the
    client holding it started a new jog 50 ms later, which ran on. A renewal that names its
    jog is refused once that jog has ended, saying why."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    for renew in range(4):
        assert rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number).ok
        rig.run(RENEW_CYCLES)
    assert rig.controller.stop().ok
    rig.run()
    braking = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert braking.error == "jog_ended" and braking.details == {"jog": number, "reason": "stopped", "lapsed": False}
    assert f"jog {number} has ended (stopped)" in braking.message
    rig.settle()
    after = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert after.error == "jog_ended" and after.details["reason"] == "stopped"
    assert rig.controller.snapshot.jog is None and rig.controller.snapshot.motion.value == "holding"
    assert rig.controller.jog([10, 0, 0, 0, 0, 0]).ok  # a new press starts a new jog


def test_a_renewal_of_a_jog_that_lapsed_says_so(rig) -> None:
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.settle()  # no renewal: the deadman lapses, the platform brakes to rest
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert refused.error == "jog_ended" and refused.details["reason"] == DEADMAN_LAPSED and refused.details["lapsed"]



def test_a_renewal_naming_no_jog_the_loop_knows_does_not_say_it_ended(rig) -> None:
    """Found from outside: a renewal naming a number no jog ever had (a client's mistake)
    was refused "jog N has ended", which hid the mistake."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.run()
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number + 1000)
    rig.run()
    verdict = rig.controller.outcome(refused.details["ticket"])
    assert verdict.error == "jog_ended"
    assert verdict.message.startswith(f"jog {number + 1000} is not under way (it ended before the last jog, or no "
                                      "jog has that number)"), verdict.message

@pytest.mark.parametrize("braked", [False, True])
def test_a_stop_after_a_lapse_ends_the_held_jog_for_good(rig, braked: bool) -> None:
    """Found in the full suite on a busy host: the dashboard's renewals came late, the jog
    lapsed, another client's stop came, and the page's next renewal, refused as lapsed,
    started a new jog that ran on. A stop (or anything that takes the motion over) after
    the lapse is why the jog ended: the renewal is refused for good, while braking from the
    lapse or after it."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.run(round(0.25 * 1e9 / rig.period_ns))  # no renewal: the deadman lapses, the platform brakes
    assert rig.controller.snapshot.jog.reason == DEADMAN_LAPSED
    if braked:
        rig.settle()
        assert rig.controller.snapshot.last_jog.reason == DEADMAN_LAPSED
    assert rig.controller.stop().ok
    rig.run()
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert refused.error == "jog_ended" and refused.details == {"jog": number, "reason": "stopped", "lapsed": False}
    rig.settle()
    assert rig.controller.snapshot.last_jog.reason == "stopped"
    assert rig.controller.jog([10, 0, 0, 0, 0, 0]).ok  # a new press starts a new jog


def test_a_move_after_a_lapse_ends_the_held_jog_for_good(rig) -> None:
    """Nor does a late client's renewal take over another client's move."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.settle()
    assert rig.controller.move([0, 0, 5, 0, 0, 0]).ok
    rig.run()
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert refused.details == {"jog": number, "reason": "replaced by a move", "lapsed": False}, refused.details
    rig.settle()
    assert rig.controller.snapshot.pose_command[2] == pytest.approx(5.0, abs=1e-6)


def test_a_lapsed_jog_restarts_in_its_place_unless_a_stop_came_after_the_lapse(rig) -> None:
    """A client whose renewal was refused as lapsed names the lapsed jog to start anew:
    refused for good if anything came after the lapse, even when the stop reaches the
    loop after the client was told of the lapse (the race a restart without a name lost)."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.settle()
    lapsed = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert lapsed.details["lapsed"]
    again = rig.controller.jog([10, 0, 0, 0, 0, 0], restarts=number)
    assert again.ok and again.details["jog"] not in (None, number), again
    rig.run(2)
    assert rig.controller.snapshot.jog.jog == again.details["jog"]
    assert rig.controller.snapshot.last_jog.jog == number  # reported ended, as replaced by the new one
    assert rig.controller.snapshot.last_jog.reason == f"replaced by jog {again.details['jog']}"

    second = again.details["jog"]
    rig.settle()  # the restarted jog lapses too; then a stop from another client, then the restart
    assert rig.controller.jog([10, 0, 0, 0, 0, 0], renews=second).details["lapsed"]
    assert rig.controller.stop().ok
    rig.run()
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], restarts=second)
    assert refused.error == "jog_ended" and refused.details == {"jog": second, "reason": "stopped", "lapsed": False}
    rig.settle()
    assert rig.controller.snapshot.jog is None and rig.controller.snapshot.motion.value == "holding"


def test_a_restart_the_loop_refuses_says_the_jog_ended_for_good(rig, monkeypatch) -> None:
    """The facade passed the restart on a snapshot from before the stop; the loop, which
    has the stop, refuses it, and the reply is not ``lapsed`` (the client would restart again)."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.settle()
    lapsed_snapshot = rig.controller.snapshot
    assert rig.controller.stop().ok
    rig.run()
    jogs = rig.controller._jogs
    monkeypatch.setattr(jogs, "_snapshot", lambda: lapsed_snapshot)  # the facade sees only the lapse
    passed = rig.controller.jog([10, 0, 0, 0, 0, 0], restarts=number)
    assert passed.details.get("pending"), passed  # this rig's loop gives its verdict when stepped
    rig.settle()
    s = rig.controller.snapshot
    assert s.jog is None and s.motion.value == "holding" and s.pose_command[0] == pytest.approx(
        lapsed_snapshot.pose_command[0], abs=1e-9)
    refusal = s.events[-1]
    assert refusal.code == "command_refused" and f"jog {number} has ended (stopped)" in refusal.message, refusal
    # As the service's facade hears that verdict: refused for good, not lapsed (its client would restart again)
    monkeypatch.setattr(jogs._submitter, "submit", lambda *arguments, **details: CommandResult.failure(
        ErrorCode.JOG_ENDED, refusal.message, **details))
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], restarts=number)
    assert refused.error == "jog_ended" and refused.details["jog"] == number and not refused.details["lapsed"], refused


def test_renews_and_restarts_together_are_refused(rig) -> None:
    rig.enabled()
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=5, restarts=5)
    assert refused.error == "invalid_argument" and "not both" in refused.message


def test_a_renewal_the_loop_finds_lapsed_says_so_as_the_facade_would(rig, monkeypatch) -> None:
    """Found in the full suite on a busy host: a renewal the facade passed on a snapshot a
    report old, whose deadman lapsed in the loop meanwhile, was refused by the loop without
    ``details.lapsed``; the dashboard took it for a stop from someone and released the held
    button for good (a lapse lets a held button jog again)."""
    rig.enabled()
    number = rig.controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
    rig.run(2)
    jogging = rig.controller.snapshot
    rig.settle()  # no renewal: the deadman lapses in the loop
    jogs = rig.controller._jogs
    snapshots = iter([jogging])  # the facade's check sees the jog under way; what follows, the loop's verdict
    monkeypatch.setattr(jogs, "_snapshot", lambda: next(snapshots, rig.controller.snapshot))
    monkeypatch.setattr(jogs._submitter, "submit", lambda *arguments, **details: CommandResult.failure(
        ErrorCode.JOG_ENDED, f"jog {number} has ended", **details))  # the loop's refusal, as its verdict comes
    refused = rig.controller.jog([10, 0, 0, 0, 0, 0], renews=number)
    assert refused.error == "jog_ended", refused
    assert refused.details == {"jog": number, "reason": DEADMAN_LAPSED, "lapsed": True}, refused.details


X_WITHIN_5 = OperatorFrames(soft_limits=SoftLimits(lower=(-5, None, None, None, None, None),
                                                   upper=(5, None, None, None, None, None)))


def _released_at(make_rig, cycle: int, frame: Frame = Frame.ZERO) -> np.ndarray:
    """A jog at -20 mm/s x towards the -5 soft limit, renewed, released ``cycle`` cycles in:
    every commanded x (mm) until at rest."""
    rig = make_rig()
    assert rig.controller.set_frames(X_WITHIN_5).ok
    rig.enabled()
    xs = []
    for n in range(cycle + 300):
        if n == cycle:
            assert rig.controller.jog([0] * 6, frame).ok
        elif n < cycle and n % RENEW_CYCLES == 0:
            assert rig.controller.jog([-20, 0, 0, 0, 0, 0], frame).ok
        rig.run()
        xs.append(rig.controller.snapshot.pose_command[0])
    assert rig.controller.snapshot.jog is None and rig.controller.snapshot.motion.value == "holding"
    return np.array(xs)


def test_a_jog_released_while_it_decelerates_onto_a_soft_limit_never_passes_it(make_rig) -> None:
    """A release (or a lapse) in the deceleration onto the limit brakes from there; a halt
    on the loop's time grid can take a cycle longer than the plan's stop, and went on to
    -5.011 mm from some release cycles (an outside review): a jog's brake never ends beyond
    where its plan ends. Released at every cycle from cruise to rest on the limit."""
    for cycle in range(118, 220):  # decelerating from cycle 124, at rest on the limit (-5 + 2 nm) from 214
        xs = _released_at(make_rig, cycle)
        assert xs.min() >= -5.0, (cycle, xs.min())


def test_a_relative_move_during_a_jog_starts_from_where_the_platform_is_not_the_jogs_horizon(rig) -> None:
    """Found from outside: a +10 mm relative move sent at x 5.5 during a 10 mm/s jog went to
    x 50, 10 mm beyond the jog's 4 s horizon (40 mm), which no one aimed at."""
    rig.enabled()
    assert rig.controller.jog([10, 0, 0, 0, 0, 0]).details["end"].startswith("the horizon")
    rig.run(250)  # 0.5 s
    x = rig.controller.snapshot.trajectory.position[0]
    assert 2.0 < x < 10.0
    moved = rig.controller.move([10, 0, 0, 0, 0, 0], relative=True)
    assert moved.ok and moved.details["goal"][0] == pytest.approx(x + 10.0, abs=1e-6), (x, moved.details["goal"])
    rig.settle()
    assert rig.controller.snapshot.pose_command[0] == pytest.approx(x + 10.0, abs=1e-6)


@pytest.mark.parametrize(("violation", "said"), [
    (Violation(ViolationKind.SOFT_TILT, 12.5, 12.000001, ""), "the soft tilt limit at 12.000001 deg"),  # was "at 12"
    (Violation(ViolationKind.SOFT_LIMIT, -3.5, -3.448287, "", axis="x"), "the soft limit on x at -3.448287 mm"),
    (Violation(ViolationKind.STROKE_HIGH, 851.0, 850.0, "", leg=3), "the stroke high limit of leg 3 at 850 mm"),
    (Violation(ViolationKind.SINGULAR, 90.0, 80.0, ""), "the near singular limit at 80"),
])
def test_a_limit_a_jog_heads_for_is_named_as_set_with_its_unit(violation, said) -> None:
    from hexactl.control.jog_planning import _limit_name

    assert _limit_name(violation) == said

