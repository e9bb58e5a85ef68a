"""The real loop thread, briefly: commands get the loop's verdict, the real-time set-up
falls back without privileges, an overrun re-anchors, a crash E-stops. Nothing here
asserts on timing figures."""

import functools
import gc
import os
import sys
import time

import pytest

from hexactl.control import realtime
from hexactl.control.config import ControllerConfig, LoopConfig
from hexactl.control.hardware import EstopCause
from hexactl.control.local_controller import LocalController
from hexactl.control.loop import ControlLoop, next_deadline
from hexactl.control.realtime import RealtimeConfig
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.sim.ideal_actuators import IdealActuators
from tools.serving import wait_until


wait_for = functools.partial(wait_until, timeout_s=10.0, poll_s=0.005)


@pytest.mark.parametrize("rate_hz", [500.0, 1000.0])
def test_the_thread_runs_commands_to_completion(geometry, rate_hz):
    actuators = IdealActuators(sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, [0] * 6)))
    config = ControllerConfig(loop=LoopConfig(rate_hz=rate_hz))
    controller = LocalController.in_thread(actuators, geometry, "nominal", config=config)
    gc_was_enabled, switch_before = gc.isenabled(), sys.getswitchinterval()
    report = controller.start()
    try:
        assert report.gc_managed and not gc.isenabled()
        enabled = controller.enable()
        assert enabled.ok and "pending" not in enabled.details  # the loop's verdict, not just queued
        assert controller.move([20, 0, 10, 0, 1, 0], duration=0.2).ok
        wait_for(lambda: controller.telemetry().pose_command == pytest.approx((20, 0, 10, 0, 1, 0), abs=1e-9),
                 "the move's end")
        refused = controller.move([20, 0, 10, 0, 1, 0], speed=3.0)
        assert refused.error == "invalid_argument"
        with pytest.raises(RuntimeError):
            controller.step(time.monotonic_ns())
        telemetry = controller.telemetry()
        assert telemetry.loop.rate_hz == rate_hz and telemetry.loop.cycles > 0
        assert telemetry.loop.missed <= telemetry.loop.cycles
        assert 0 <= telemetry.loop.lateness_us.p50 <= telemetry.loop.lateness_us.max
        assert controller.status().details["loop_running"]
    finally:
        controller.shutdown()
    assert gc.isenabled() == gc_was_enabled and sys.getswitchinterval() == switch_before



def test_a_release_is_answered_with_what_the_loop_released(geometry):
    """Found from outside: the reply came from the facade's snapshot, a report behind the
    loop, and said "nothing to release" for a jog just started that the loop then braked."""
    actuators = IdealActuators(sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, [0] * 6)))
    controller = LocalController.in_thread(actuators, geometry, "nominal")
    controller.start()
    try:
        assert controller.enable().ok
        number = controller.jog([10, 0, 0, 0, 0, 0]).details["jog"]
        released = controller.jog([0] * 6)  # at once: the facade's snapshot may not show the jog yet
        assert released.ok and released.message in (f"jog {number} released: braking to rest",
                                                     f"jog {number} released (at rest)")
        assert controller.jog([0] * 6).message == "nothing to release: no jog is under way"
    finally:
        controller.shutdown()

def test_realtime_set_up_falls_back_and_says_why(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    monkeypatch.setattr(realtime, "_mlockall", lambda: "Operation not permitted")
    config = RealtimeConfig(fifo_priority=80, cpus=(0,), lock_memory=True, manage_gc=False, switch_interval_s=None)
    loop = ControlLoop(lambda now: None, LoopConfig(realtime=config), on_crash=lambda: None)
    report = loop.start()
    try:
        assert report.fifo_priority is None and report.cpus is None and not report.memory_locked
        assert len(report.notes) == 3 and all("not permitted" in note for note in report.notes)
        wait_for(lambda: loop.stats.cycles > 10, "more than ten cycles")
    finally:
        loop.stop()


def test_deadlines_follow_the_grid_and_re_anchor_after_an_overrun():
    period = 2_000_000
    assert next_deadline(10 * period, 10 * period + 300_000, period) == (11 * period, 0)  # on time
    assert next_deadline(10 * period, 11 * period + 1_500_000, period) == (11 * period, 0)  # late: runs at once
    # Five periods behind: no burst of five cycles, one now and the grid restarts here.
    end = 16 * period + 700_000
    assert next_deadline(10 * period, end, period) == (end, 5)


def test_an_overrun_in_the_thread_is_counted_as_skipped():
    period_ns = LoopConfig().period_ns
    calls = []

    def cycle(now_ns):
        calls.append(now_ns)
        if len(calls) == 20:
            time.sleep(5 * period_ns / 1e9)  # a five-period stall

    loop = ControlLoop(cycle, LoopConfig(realtime=RealtimeConfig(manage_gc=False)), on_crash=lambda: None)
    loop.start()
    try:
        wait_for(lambda: len(calls) > 40, "more than forty cycles")
    finally:
        loop.stop()
    # Sleeping never returns early, so at least four whole deadlines had passed.
    assert loop.stats.skipped >= 4 and loop.stats.missed >= loop.stats.skipped


def test_a_crashing_cycle_estops_and_commands_report_it(geometry):
    actuators = IdealActuators(sensor_setpoints(geometry.legs, absolute_from_relative(geometry.home, [0] * 6)))
    controller = LocalController.in_thread(actuators, geometry, "nominal", config=ControllerConfig(loop=LoopConfig(
        realtime=RealtimeConfig(manage_gc=False))))
    actuators.read_feedback = lambda: 1 / 0  # a bug in a cycle
    controller.start()
    wait_for(lambda: not controller.status().details["loop_running"], "the crashed loop to end")
    assert actuators.estops == 1 and actuators.last_estop_cause is EstopCause.CONTROLLER_FAULT
    assert "ZeroDivisionError" in controller.status().details["loop_failure"]
    assert controller.enable().error == "loop_failed"
    assert controller.stop().error == "loop_failed"
