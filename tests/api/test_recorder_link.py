"""The data recorder's rows cross the loop link losslessly: reports the pipe has no room
for are dropped, the rows they would have carried wait for the next report that fits."""

from __future__ import annotations

import multiprocessing

from hexactl.application import loop_link
from hexactl.application.loop_link import LoopExchange, RemoteLoop
from hexactl.control import commands as cmd
from hexactl.control.config import ControllerConfig
from hexactl.control.host import LoopThread
from hexactl.control.planning import ActiveGeometry
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.inverse import sensor_setpoints
from hexactl.kinematics.pose import absolute_from_relative
from hexactl.sim.ideal_actuators import IdealActuators
from tests.api.test_service import wait_for
from tests.control.conftest import SimClock

ROWS = 600


def test_rows_survive_reports_dropped_on_a_full_pipe(nominal: Geometry, monkeypatch) -> None:
    monkeypatch.setattr(loop_link, "REPORT_INTERVAL_S", 0.0)  # a report after every cycle
    clock = SimClock()
    start = sensor_setpoints(nominal.legs, absolute_from_relative(nominal.home, (0.0,) * 6))
    thread = LoopThread(IdealActuators(start, clock_ns=clock), ActiveGeometry.of(nominal, "nominal"),
                        ControllerConfig(), clock_ns=clock)
    pipes = multiprocessing.get_context("spawn")
    commands_in, commands_out = pipes.Pipe(duplex=False)
    reports_in, reports_out = pipes.Pipe(duplex=False)
    exchange = LoopExchange(thread, commands_in, reports_out).start()

    def cycle() -> None:
        thread.loop.step(clock.advance(thread.loop.period_ns))
        exchange()

    thread.submit(cmd.StartRecording(1, 42, "link", 1, ROWS))
    # Nobody reads the reports yet: the pipe fills and reports are dropped.
    while exchange.reports_dropped < 50:
        cycle()
    remote = RemoteLoop(commands_out, reports_in)
    try:
        rows: list = []
        for _ in range(ROWS):  # each row is recorded by then; the backlog drains 64 a report
            cycle()

        def arrived() -> bool:
            exchange()  # sends what is still waiting (the recording has ended)
            rows.extend(remote.take_recorded())
            return len(rows) >= ROWS

        wait_for(arrived, "every recorded row")
        cycles = [row[1] for row in rows]
        assert len(rows) == ROWS and cycles == list(range(cycles[0], cycles[0] + ROWS))
        assert {row[0] for row in rows} == {42}
        assert remote.snapshot.recorder.lost == 0
        assert remote.report(0.25).recorded == ()  # the rows went to take_recorded, not the latest report
    finally:
        remote.close()
        exchange.close()
