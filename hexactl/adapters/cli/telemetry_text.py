"""A telemetry record (docs/api.md, "Telemetry") as text, with units: ``status``, ``monitor
--once`` and ``monitor`` when its output is not a terminal print it, and the full-screen
``monitor`` (:mod:`hexactl.adapters.cli.monitor`) shows the same values.

Standard library only at the top (start-up: :mod:`hexactl.adapters.cli.common`).
"""

from __future__ import annotations

from typing import Any

from hexactl.control.results import OTHER_CONTROLLER_WINDOW_S, REPORT_SILENT_S
from hexactl.kinematics.axes import POSE_AXES, POSE_UNITS, bounds_text


def format_telemetry(record: dict[str, Any], calibration_source: str | None = None) -> str:
    """A telemetry record as an aligned block of text (poses in mm and deg, legs in mm);
    with ``calibration_source`` (the status reply's), where the calibration came from."""
    loop = record["loop"]
    lines = [
        *silent_loop_lines(loop),
        ("state", f"{record['state']}, {record['motion']}"),
        ("pose command", pose_text(record.get("pose_command"))),
        ("pose measured", pose_text(record.get("pose_measured"))),
        ("goal", pose_text(record["goal"]) if record.get("goal") else "none"),
        ("remaining", remaining_text(record.get("remaining_s"))),
        ("leg set-points", legs_text(record.get("leg_setpoints"))),
        ("leg feedback", legs_text(record.get("leg_feedback"))),
        ("legs", leg_states_text(record.get("legs"))),
        *other_controller_lines(record.get("other_controller")),
        *link_lines(record.get("link")),
        *frames_lines(record),
        ("locked leg", f"L{record['locked_leg']}" if record.get("locked_leg") else "none"),
        ("calibration", record["calibration_id"] + (f" (from {calibration_source})" if calibration_source else "")),
        ("sequence", sequence_text(record.get("sequence"))),
        ("jog", jog_text(record.get("jog"))),
        ("wave", wave_text(record.get("wave"))),
        ("stream", stream_text(record.get("stream"), record.get("last_stream"))),
        *stream_input_lines(record.get("stream_input")),
        ("recording", recording_text(record.get("recording"))),
        ("faults", "; ".join(fault_text(fault) for fault in record.get("faults") or []) or "none"),
        ("last event", event_text(events[-1], record["t"]) if (events := record.get("events")) else "none"),
        ("loop", loop_text(loop)),
        ("lateness µs", percentiles_text(loop["lateness_us"])),
        ("compute µs", percentiles_text(loop["compute_us"])),
        ("real-time", realtime_text(record.get("realtime"))),
    ]
    return "\n".join(f"{label:<15}{value}" for label, value in lines)


def silent_loop_lines(loop: dict[str, Any]) -> list[tuple[str, str]]:
    """A first row saying the record is old when the loop's process has sent nothing for
    over :data:`REPORT_SILENT_S` (a service older than this field: none)."""
    age = loop.get("report_age_s") or 0.0
    if age <= REPORT_SILENT_S:
        return []
    return [("NO LOOP REPORT", f"for {age:.1f} s: the control loop's process is stopped or hung (its actuators stop "
                               "on their watchdogs; it is sent no command but stop, abort and estop, which wait for it); "
                               "what follows is its last report")]


def other_controller_lines(heard: dict[str, Any] | None) -> list[tuple[str, str]]:
    """A row naming another controller heard on the bus, once one has been (a service older
    than this field: none)."""
    if heard is None:
        return []
    if heard["age_s"] > OTHER_CONTROLLER_WINDOW_S:
        return [("other ctrl", f"{heard['frame']} last heard {heard['age_s']:.1f} s ago")]
    return [("OTHER CTRL", f"{heard['frame']} heard {heard['age_s']:.3f} s ago: another controller drives these "
                           "actuators; enable is refused until it stops (candump on the CAN interface shows it)")]


BUS_STATE_TEXT = {
    "active": "CAN bus active",
    "warning": "CAN bus WARNING: error counters high, frames still get through",
    "passive": "CAN bus ERROR-PASSIVE: frames get through with errors; check the wiring, its two terminations and "
               "the bit rate before it goes bus-off",
    "bus_off": "CAN bus OFF: this controller has left the bus and sends nothing (enable says what to check)",
    "down": "CAN interface DOWN: closed or missing, nothing is sent or heard",
}
"""The link's bus states (telemetry's ``link.bus_state``) for people."""


def link_lines(link: dict[str, Any] | None) -> list[tuple[str, str]]:
    """A row on the link to the actuators: its bus state, send failures and note (a
    service older than this field, or before the first read: none). In capitals when the
    bus is not healthy."""
    if link is None:
        return []
    state = link["bus_state"]
    failures = link["send_failures"]
    parts = [BUS_STATE_TEXT.get(state, f"CAN bus {state}"),
             f"{failures} send failure{'' if failures == 1 else 's'}" if failures else "no send failures"]
    if link["detail"]:
        parts.append(link["detail"])
    return [("link" if state == "active" else "LINK", "; ".join(parts))]


def pose_text(pose: list[float] | None) -> str:
    """``x 1.000 mm  …  yaw 5.000 deg``; ``unknown`` for None."""
    if pose is None:
        return "unknown"
    return "  ".join(f"{axis} {value:8.3f} {unit}" for axis, unit, value in zip(POSE_AXES, POSE_UNITS, pose))


NO_FRAMES = {"work": [0.0] * 6, "tool": [0.0] * 6, "soft_limits": {"lower": [None] * 6, "upper": [None] * 6,
                                                                   "max_tilt_deg": None}}
"""A record's ``frames`` when the operator has set none."""


def frames_lines(record: dict[str, Any]) -> list[tuple[str, str]]:
    """The operator's frames, soft limits and the tool's pose in the work frame, as
    (label, text) rows; one row when none are set."""
    frames = record.get("frames")
    if not frames or frames == NO_FRAMES:
        return [("frames", "none (poses relative to the zero posture)")]
    in_work = [("tool in work", pose_text(record["tool_pose_command"]))] if "tool_pose_command" in record else []
    outside = [("OUTSIDE", "; ".join(record["outside_soft_limits"]))] if record.get("outside_soft_limits") else []
    return [("work frame", pose_text(frames["work"])), ("tool frame", pose_text(frames["tool"])), *in_work,
            ("soft limits", soft_limits_text(frames["soft_limits"])), *outside]


def soft_limits_text(limits: dict[str, Any]) -> str:
    """``x -50..50 mm, z ≥ -10 mm, tilt ≤ 5 deg``, or ``none`` (:func:`~hexactl.kinematics.axes.bounds_text`)."""
    return bounds_text(limits["lower"], limits["upper"], limits.get("max_tilt_deg"))


def legs_text(values: list[float | None] | None) -> str:
    """``L1 425.000  …  L6 425.000 mm`` (``?`` for a leg not heard from); ``unknown`` for None."""
    if values is None:
        return "unknown"
    return "  ".join(f"L{leg} {'?' if value is None else format(value, '8.3f'):>8}"
                     for leg, value in enumerate(values, start=1)) + " mm"


SILENT_AFTER_S = 0.5
"""A leg whose last report is older than this is named as silent (they report every few ms)."""


def leg_state_text(leg: dict[str, Any]) -> str:
    """One leg's state with its fault bits, named, when it has any: ``enabled``,
    ``fault: comm_timeout, sensor (0x81)``; as :func:`hexactl.control.hardware.fault_text`
    writes them, which is not imported because ``status`` loads no control module."""
    bits = leg["fault_bits"]
    return leg["state"] + (f": {', '.join(leg['fault_names'])} ({bits:#x})" if bits else "")


def leg_states_text(legs: list[dict[str, Any]] | None) -> str:
    """``all enabled``, or each leg's state with its fault bits (``L5 fault: sensor (0x80)``), then
    the legs not heard from lately; ``unknown`` for None."""
    if not legs:
        return "unknown"
    states = [leg_state_text(leg) for leg in legs]
    text = f"all {states[0]}" if len(set(states)) == 1 else "  ".join(
        f"L{number} {state}" for number, state in enumerate(states, start=1))
    silent = [f"L{number} " + ("never" if leg["report_age_s"] is None else f"{leg['report_age_s']:.1f} s")
              for number, leg in enumerate(legs, start=1)
              if leg["report_age_s"] is None or leg["report_age_s"] > SILENT_AFTER_S]
    return text + (f"; no report lately: {', '.join(silent)}" if silent else "")


def remaining_text(remaining_s: float | None) -> str:
    return "at rest" if remaining_s is None else f"{remaining_s:.2f} s"


def sequence_text(sequence: dict[str, Any] | None) -> str:
    """``NAME i/n (phase)``, or ``none``."""
    return f"{sequence['name']} {sequence['index']}/{sequence['total']} ({sequence['phase']})" if sequence else "none"


def jog_text(jog: dict[str, Any] | None) -> str:
    """``jog 12 jogging x 10 mm/s in zero, to the soft limit on x at 5 mm (renew within 0.15 s)``, or ``none``."""
    if not jog:
        return "none"
    velocity = ", ".join(f"{axis} {value:g} {unit}/s" for axis, unit, value in zip(POSE_AXES, POSE_UNITS, jog["velocity"])
                         if value)
    return (f"jog {jog['jog']} {jog['phase']} {velocity} in {jog['frame']}, to {jog['end']} "
            f"(renew within {jog['renew_within_s']:.2f} s)")


def wave_text(wave: dict[str, Any] | None) -> str:
    """``cycle 2 of 5 (steady)`` while a wave plays, ``finished in cycle 5 of 5`` once over; or ``none``."""
    if not wave:
        return "none"
    if wave["phase"] in ("ramp_in", "steady", "ramp_out"):
        return f"cycle {wave['cycle']} of {wave['cycles']} ({wave['phase']})"
    return f"{wave['phase']} in cycle {wave['cycle']} of {wave['cycles']}"


def stream_text(stream: dict[str, Any] | None, last: dict[str, Any] | None) -> str:
    """``stream 7 from sim-1 in work: following, 1200 targets (sample 1234, 0.004 s ago, 1.2 ms from arrival)``;
    ``none (stream 7 ended: timeout …, 1200 targets)``; or ``none``."""
    if stream:
        newest = (f" (sample {stream['last_sequence']}, {stream['since_target_s']:.3f} s ago"
                  + (f", {stream['latency_ms']:.1f} ms from arrival)" if stream.get("latency_ms") is not None else ")")
                  if stream.get("last_sequence") is not None else "")
        return (f"stream {stream['stream']} from {stream['source']} in {stream['frame']}: {stream['phase']}, "
                f"{stream['targets']} targets{newest}")
    if last:
        return f"none (stream {last['stream']} ended: {last['reason']}, {last['targets']} targets)"
    return "none"


_DROPPED = (("malformed", "malformed"), ("out_of_order", "out of order"), ("other_sender", "from another sender"),
            ("no_stream", "with no stream open"), ("loop_behind", "dropped, the loop behind"), ("failed", "failed"))


def stream_input_lines(received: dict[str, Any] | None) -> list[tuple[str, str]]:
    """The pose stream's receiver, once it has read anything or stopped: what it read and
    dropped, and its last problem (``STREAM INPUT`` in capitals once it has stopped)."""
    if not received or (received["running"] and not received["received"]):
        return []
    if not received["running"]:
        return [("STREAM INPUT", "stopped: stream_open is refused until the service restarts (its log says why)")]
    dropped = [f"{received[key]} {what}" for key, what in _DROPPED if received.get(key)]
    counted = [f"{received['rate_hz']} Hz", f"{received['received']} read", f"{received['forwarded']} to the loop",
               *([f"{received['clamped']} clamped"] if received.get("clamped") else []), *dropped]
    problem = f"; last problem: {received['last_problem']}" if received.get("last_problem") else ""
    stream = f"stream {received['stream']}: " if received.get("stream") is not None else ""
    return [("stream input", f"{stream}{', '.join(counted)}{problem}")]


def recording_text(recording: dict[str, Any] | None) -> str:
    """``run2 recording 1200/2500 rows``, ``run2 done 2500/2500 rows (duration)``, with rows lost if any; or ``none``."""
    if not recording:
        return "none"
    lost = f", {recording['lost']} lost" if recording.get("lost") else ""
    ended = f" ({recording['ended']})" if recording.get("ended") else ""
    file = recording.get("file") or {}
    said = (f"; its file: write_failed, rows missing ({recording['name']}.json says why)"
            if file.get("ended") == "write_failed" else "")
    said += "; FAULT or ESTOP during it (hexactl events says when)" if file.get("faults_during") else ""
    return (f"{recording['name']} {recording['state']} {recording['rows']}/{recording['rows_requested']} rows{lost}"
            f"{ended}{said}")


def event_text(event: dict[str, Any], now_t: float) -> str:
    """One of the loop's events as ``code: message, sent by SENDER (N s ago)``, its age at
    the record time ``now_t`` (s)."""
    sender = f", sent by {event['sender']}" if event.get("sender") else ""
    return f"{event['code']}: {event['message']}{sender} ({now_t - event['t']:.1f} s ago)"


def fault_text(fault: dict[str, Any]) -> str:
    where = f"leg {fault['leg']}: " if fault.get("leg") else ""
    return f"{where}{fault['code']} ({fault['message']})"


def loop_text(loop: dict[str, Any]) -> str:
    return f"{loop['rate_hz']:g} Hz, {loop['cycles']} cycles, {loop['missed']} missed"


def percentiles_text(values: dict[str, float]) -> str:
    return f"p50 {values['p50']:.0f}  p99 {values['p99']:.0f}  p99.9 {values['p999']:.0f}  max {values['max']:.0f}"


def realtime_text(realtime: dict[str, Any] | None) -> str:
    if not realtime:
        return "unknown"
    # Here, not at the top: the module loads pydantic, which the light commands do not need.
    from hexactl.control.realtime import RealtimeReport, describe

    return describe(RealtimeReport(**realtime))
