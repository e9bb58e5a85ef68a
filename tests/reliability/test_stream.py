"""A pose stream on the whole service, watched by the independent bus monitor (issue 15):
a stream that runs far beyond the workspace brings the platform to rest on its boundary,
smoothly, and no set-point on the bus leaves the stroke or exceeds the legs' speed."""

from __future__ import annotations

import time

from hexactl.adapters.api.client import HexactlClient
from hexactl.adapters.api.stream_client import PoseStream
from hexactl.kinematics.geometry import Geometry
from hexactl.kinematics.workspace import assess_pose
from tests.api.test_service import status, wait_for
from tests.reliability.support import recover, tolerating_stalls


def test_a_stream_far_out_of_reach_stops_on_the_boundary_with_every_setpoint_in_limits(
        client: HexactlClient, monitor, nominal: Geometry) -> None:
    def scenario() -> None:
        recover(client)
        setpoints_before = monitor.counts.get("setpoints", 0)
        with PoseStream(client, "far out", timeout_ms=1000) as stream:
            start = time.monotonic()
            for n in range(300):  # z from here to 900 mm in 1.5 s at 200 Hz: the boundary is at about 250 mm
                stream.send((0.0, 0.0, 3.0 * n, 0.0, 0.0, 0.0))
                time.sleep(max(0.0, start + (n + 1) / 200 - time.monotonic()))
            record = status(client)
            deadline = time.monotonic() + 60.0  # bounds a hang only: the boundary is ~250 mm away at ~40 mm/s
            while record["motion"] != "holding" or record["stream"] is None:  # held far out, as a stuck output is
                assert time.monotonic() < deadline and record["stream"] is not None, record["last_stream"]
                for _ in range(20):
                    stream.send((0.0, 0.0, 900.0, 0.0, 0.0, 0.0))
                    time.sleep(0.01)
                record = status(client)
            assert record["state"] == "enabled" and record["stream"] is not None, (record["faults"], record["last_stream"])
            assert record["stream_input"]["clamped"] > 0 and record["loop"]["guard_clamps"] == 0
        monitor.catch_up()
        assert monitor.counts.get("setpoints", 0) > setpoints_before  # it watched this stream's set-points
        pose = record["pose_command"]
        assert pose[2] > 150.0 and assess_pose(nominal, pose).ok
        assert not assess_pose(nominal, [pose[0], pose[1], pose[2] + 2.0, *pose[3:]]).ok  # on the boundary
        client.call("move", pose=[0.0] * 6, duration=3.0)
        wait_for(lambda: status(client)["motion"] == "holding", "the way back")

    tolerating_stalls(client, scenario)
