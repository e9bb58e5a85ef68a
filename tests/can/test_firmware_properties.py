"""Whatever frames arrive, a simulated actuator never leaves its stroke and never moves faster
than its speed limit."""

from __future__ import annotations

from hypothesis import event, given, settings, target
from hypothesis import strategies as st

from firmware_proto import codec
from firmware_proto.codec import SETPOINT_MAX_UM, SETPOINT_MIN_UM, CommandCode, EStopReason, LoopRate
from hexactl.sim.actuator_firmware import ActuatorFirmware, ActuatorParams

LOW, HIGH = 0, 850_000
PARAMS = ActuatorParams(soft_limits_um=(LOW, HIGH), max_velocity_um_s=400_000.0)
STEP_S = 0.0005

# Within the step rule at every loop rate (400 µm per ms) and mostly one way: it travels.
near = st.integers(-150, 400).map(lambda delta: ("delta", delta))
setpoint = st.one_of(
    near,
    near,
    near,
    near,
    near,
    st.integers(SETPOINT_MIN_UM, SETPOINT_MAX_UM).map(lambda value: ("absolute", value)),
    st.sampled_from([("absolute", LOW), ("absolute", HIGH), ("absolute", HIGH + 1), ("absolute", LOW - 1)]),
)
# Counter steps: mostly the next cycle, sometimes stale (0) or after missed cycles.
cycle = st.tuples(st.just("cycle"), st.sampled_from([1, 1, 1, 1, 1, 0, 2, 3]), setpoint)

disruption = st.one_of(
    st.tuples(st.just("counter"), st.integers(0, 255), setpoint),  # any counter
    st.tuples(st.just("command"), st.sampled_from(list(CommandCode)), st.sampled_from([2, 5, 100])),
    st.tuples(st.just("wait"), st.integers(1, 40)),  # steps of 0.5 ms
    st.tuples(st.just("estop"),),
    st.tuples(st.just("corrupt"), st.integers(0, 7)),
)
# Mostly a stream of cycles, so that the drive travels between the disruptions.
action = st.integers(0, 99).flatmap(lambda draw: cycle if draw < 90 else disruption)


@settings(max_examples=150, deadline=None)
@given(
    start_um=st.one_of(st.integers(LOW, HIGH), st.sampled_from([LOW, HIGH, HIGH - 50, LOW + 50])),
    loop_rate=st.sampled_from([LoopRate.HZ_250, LoopRate.HZ_500, LoopRate.HZ_1000]),
    actions=st.lists(action, min_size=10, max_size=200),
)
def test_never_outside_the_stroke_nor_faster_than_the_speed_limit(start_um, loop_rate, actions):
    fw = ActuatorFirmware(1, start_um, PARAMS)
    t = 0.0
    counter = 0
    sequence = 0
    trace = [(t, fw.position_um)]

    def run(frames):
        for can_id, payload in frames:
            fw.receive(can_id, payload, t)
        trace.append((t, fw.position_um))

    def tick(steps):
        nonlocal t
        for _ in range(steps):
            t += STEP_S
            fw.advance(t)
            trace.append((t, fw.position_um))
            assert abs(fw.velocity_um_s) <= PARAMS.max_velocity_um_s

    tick(1)
    run([codec.encode_command(1, CommandCode.ENABLE, sequence, loop_rate, 5)])
    for kind, *arguments in actions:
        if kind in ("cycle", "counter"):
            step_or_counter, (mode, value) = arguments
            counter = (counter + step_or_counter) & 0xFF if kind == "cycle" else step_or_counter
            wanted = round(fw.target_um) + value if mode == "delta" else value
            wanted = min(max(wanted, SETPOINT_MIN_UM), SETPOINT_MAX_UM)
            run(codec.encode_setpoints(counter, [wanted] * 6))
            tick(round(1 / loop_rate / STEP_S))
        elif kind == "command":
            code, watchdog = arguments
            sequence = (sequence + 1) & 0xFF
            rate = loop_rate if code is CommandCode.ENABLE else LoopRate.NOT_SET
            run([codec.encode_command(1, code, sequence, rate, watchdog if code is CommandCode.ENABLE else 0)])
        elif kind == "wait":
            tick(arguments[0])
        elif kind == "estop":
            run([codec.encode_estop(EStopReason.OPERATOR)])
        else:
            can_id, payload = codec.encode_setpoints(counter, [HIGH] * 6)[0]
            run([(can_id, bytes(b ^ (1 << arguments[0]) if i == 0 else b for i, b in enumerate(payload)))])
    tick(400)  # 200 ms more: whatever state it is in, it comes to rest inside the stroke

    travel = max(abs(p - start_um) for _, p in trace)
    event("moved" if travel > 1_000 else "stayed")  # the statistics show both kinds are explored
    target(travel)
    for (t0, p0), (t1, p1) in zip(trace, trace[1:]):
        assert LOW <= p1 <= HIGH
        assert abs(p1 - p0) <= PARAMS.max_velocity_um_s * (t1 - t0) + 1e-6
