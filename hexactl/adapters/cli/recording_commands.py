"""``hexactl record`` (the service's data recorder) and ``hexactl plot`` (a recording to a PNG).

``record NAME --duration S`` asks the running service to record (docs/api.md, "Data
recorder"); with ``--wait`` it returns once the file is written, printing its path, and
exits 1 saying why if the recording ended badly. ``record --stop`` ends one early.
``plot RECORDING.csv`` draws one panel per signal group, with the units of the header
and the title from the side file (``RECORDING.json``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexactl.adapters.api.protocol import MAX_RECORDING_DIVISOR, MAX_RECORDING_S
from hexactl.adapters.files.recording_file import SIGNALS  # the service checks them again
from hexactl.adapters.cli.common import (CliError, check_output, connect, named_path, positive_up_to,
                                        whole_number_in, write_failed)

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

EXIT_OK, EXIT_REFUSED, EXIT_NO_ANSWER = 0, 1, 2

WAIT_POLL_S = 0.2
WAIT_SLACK_S = 30.0
"""``--wait`` gives up this long after the recording should have ended (its duration, plus
the wait for the next motion with ``--on-motion``: there, it waits as long as it takes)."""

GOOD_ENDINGS = ("duration", "stopped")

PLOT_BUCKETS = 2000
"""A line of ``plot`` has at most twice this many points (:func:`envelope`)."""

IMAGE_FORMATS = ("png", "svg", "pdf")
"""What ``plot`` writes, by the image's ending."""

_GROUPS = (  # (column prefix, panel title): one panel each, in this order
    ("pose_command_", "commanded pose"), ("pose_measured_", "measured pose"), ("setpoint_", "set-points"),
    ("feedback_", "feedback"), ("lateness_", "loop lateness"), ("compute_", "loop compute"),
)


def register(subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    from hexactl.adapters.cli.service_commands import client_parser  # the client options, shared

    record = subparsers.add_parser(
        "record", parents=[client_parser()], help="record the control loop's signals to CSV on the service's machine",
        description="Record the control loop's signals, cycle by cycle, to NAME.csv (and NAME.json, the "
        "configuration) in the service's first data directory.")
    record.add_argument("name", metavar="NAME", nargs="?", help="the files' name, without extension or directory")
    record.add_argument("--duration", type=positive_up_to(MAX_RECORDING_S, "s"), metavar="S",
                        help=f"how long to record, s (at most {MAX_RECORDING_S:g})")
    record.add_argument("--signals", type=_signals, metavar="A,B", help=f"what to record (default all): {','.join(SIGNALS)}")
    record.add_argument("--frame", choices=("zero", "work"), default="zero",
                        help="the poses: relative to the zero posture (default), or the tool's pose in the work frame")
    record.add_argument("--divisor", type=whole_number_in(1, MAX_RECORDING_DIVISOR), default=1, metavar="N",
                        help=f"every N-th cycle (default 1: every cycle; at most {MAX_RECORDING_DIVISOR})")
    record.add_argument("--on-motion", action="store_true", help="start with the next motion instead of now")
    record.add_argument("--wait", action="store_true", help="return when the file is written, printing its path "
                        "(exit 1, saying why, if the recording ended badly)")
    record.add_argument("--stop", action="store_true", help="end the recording under way early (no NAME)")
    record.set_defaults(run=run_record)
    plot = subparsers.add_parser("plot", parents=[common], help="plot a recording (CSV) to a PNG",
                                 description="Plot a recording made by `hexactl record`: one panel per signal group.")
    plot.add_argument("recording", metavar="RECORDING", type=named_path, help="the recording's CSV file")
    plot.add_argument("-o", "--out", type=named_path, metavar="IMAGE", help="the image, its format by its ending: "
                      f"{', '.join('.' + f for f in IMAGE_FORMATS)} (default: RECORDING with .png; replaced if there)")
    plot.set_defaults(run=run_plot)


def _signals(text: str) -> list[str]:
    signals = [part.strip() for part in text.split(",") if part.strip()]
    if not signals:  # an empty list would be dropped, and all of them recorded
        raise argparse.ArgumentTypeError(f"name at least one signal (leave --signals out to record all): "
                                         f"choose among {','.join(SIGNALS)}")
    if unknown := [s for s in signals if s not in SIGNALS]:
        raise argparse.ArgumentTypeError(f"unknown {', '.join(unknown)}: choose among {','.join(SIGNALS)}")
    if twice := sorted({s for s in signals if signals.count(s) > 1}):  # as the service refuses them
        raise argparse.ArgumentTypeError(f"{', '.join(twice)} named more than once: name each signal once")
    return signals


def record_request(arguments: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """The command and fields ``hexactl record`` sends; CliError for a contradiction."""
    if arguments.stop:
        if arguments.name or arguments.duration:
            raise CliError("--stop takes no NAME and no --duration")
        return "record_stop", {}
    if not arguments.name or arguments.duration is None:
        raise CliError("give NAME and --duration S (or --stop)")
    name = arguments.name[:-4] if arguments.name.endswith(".csv") else arguments.name
    fields: dict[str, Any] = {"name": name, "duration_s": arguments.duration, "frame": arguments.frame,
                              "divisor": arguments.divisor, "start": "next_motion" if arguments.on_motion else "now"}
    if arguments.signals is not None:
        fields["signals"] = arguments.signals
    return "record", fields


def run_record(arguments: argparse.Namespace) -> int:
    from hexactl.adapters.api.client import HexactlClient, ServiceUnavailable  # zmq: not for --help
    from hexactl.adapters.cli.service_commands import format_error_reply

    cmd, fields = record_request(arguments)
    client = connect(HexactlClient, arguments.api, arguments, timeout_s=arguments.timeout)
    try:
        with client:
            reply = client.request(cmd, **fields)
            if arguments.json and not arguments.wait:
                print(json.dumps(reply))
                return EXIT_OK if reply.get("ok") else EXIT_REFUSED
            if not reply.get("ok"):
                print(format_error_reply(reply), file=sys.stderr)
                return EXIT_REFUSED
            if cmd == "record_stop":
                return _report_written(reply, arguments.json, waited=False)
            print(f"ok: {reply['message']}: {reply['rows']} rows at {reply['rate_hz']:g} Hz to {reply['path']}",
                  flush=True)
            if not arguments.wait:
                return EXIT_OK
            try:
                side = _wait_written(client, fields["name"], reply, arguments.on_motion)
            except ServiceUnavailable as error:
                return _service_gone(reply["path"], error, arguments.json)
            return _report_written(side, arguments.json, waited=True)
    except ServiceUnavailable as error:
        print(f"hexactl record: {error}", file=sys.stderr)
        return EXIT_NO_ANSWER


def _service_gone(csv_path: str, error: Exception, as_json: bool) -> int:
    """``--wait``, and the service stopped answering (stopped by a signal, most often, which
    ends the recording and writes its files first): the side file, when it is on this
    machine, says how it ended; else where to look."""
    side_path = Path(csv_path).with_suffix(".json")
    try:
        side = json.loads(side_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        side = None
    if isinstance(side, dict) and side.get("csv") == csv_path:
        print(f"hexactl record: the service stopped answering ({error}); its side file {side_path} says how the "
              "recording ended:", file=sys.stderr)
        return _report_written(side, as_json, waited=True)
    print(f"hexactl record: the service stopped answering during the recording ({error}); how it ended is in "
          f"{side_path.name} beside {csv_path} on the service's machine (not here)", file=sys.stderr)
    return EXIT_NO_ANSWER


def _wait_written(client: Any, name: str, reply: dict[str, Any], on_motion: bool) -> dict[str, Any]:
    """Poll ``record_status`` until recording ``name``'s file is written; its side file."""
    deadline = time.monotonic() + float(reply["duration"]) + WAIT_SLACK_S
    while True:
        state = client.request("record_status")
        if state.get("state") == "done" and state.get("name") == name:  # one at a time: the last one done is ours
            return state
        recorder = (client.request("status")["status"].get("recording") or {}) if on_motion else {}
        if recorder.get("state") == "armed":
            deadline = time.monotonic() + float(reply["duration"]) + WAIT_SLACK_S  # no motion yet: keep waiting
        if time.monotonic() > deadline:
            return {"ended": "lost", "csv": reply["path"],
                    "problem": f"not written {WAIT_SLACK_S:g} s after it should have ended"}
        time.sleep(WAIT_POLL_S)


def _report_written(side: dict[str, Any], as_json: bool, *, waited: bool) -> int:
    """Print where the recording was written; 1 (saying why) if it ended badly, and, for
    who ``waited`` for it, if it was stopped short of its rows (``record --stop`` itself
    asked for that)."""
    if as_json:
        print(json.dumps(side))
    problems = []
    if problem := side.get("problem"):
        problems.append(problem)
    elif side.get("write_error"):
        problems.append(f"it could not be written whole: {side['write_error']}")
    elif side.get("ended") not in GOOD_ENDINGS:
        problems.append(f"it ended early: {side.get('ended')} (the service stopped, or its loop failed)")
    elif waited and side.get("ended") == "stopped" and side.get("rows_written", 0) < side.get("rows_requested", 0):
        # --wait && analyse NAME.csv must not go on with a recording cut short (as move --wait does not)
        problems.append(f"it was stopped after {side.get('rows_written', 0)} of its {side['rows_requested']} rows "
                        "(record --stop, or the service stopping)")
    if side.get("cycles_missing"):
        problems.append(f"{side['cycles_missing']} cycles are missing ({side.get('rows_lost', 0)} rows lost)")
    if side.get("side_file_error"):
        problems.append(f"its side file was not written: {side['side_file_error']}")
    if side.get("faults_during"):
        problems.append("the controller was in FAULT or ESTOP during it: the motion recorded is not the one "
                        "planned (the service's log says when)")
    if not as_json:
        print(f"{side.get('csv')}: {side.get('rows_written', 0)} rows, ended: {side.get('ended')}")
        if (gap := held_up_gap(side)) is not None:
            print(f"note: rows up to {gap:.3f} s apart, every {1 / side['rate_hz']:g} s planned: the control loop was "
                  "held up (its cycles numbered on, late); t_s has each row's time")
    if problems:
        print(f"hexactl record: {'; '.join(problems)}", file=sys.stderr)
        return EXIT_REFUSED
    return EXIT_OK


def held_up_gap(side: dict[str, Any]) -> float | None:
    """The side file's longest gap between rows, s, when it is over one and a half times the
    rows' interval (a row came late by half an interval or more), else None."""
    gap, rate = side.get("longest_row_gap_s"), side.get("rate_hz")
    return gap if gap is not None and rate and gap > 1.5 / rate else None


# -- plot ----------------------------------------------------------------------------


def run_plot(arguments: argparse.Namespace) -> int:
    path: Path = arguments.recording
    out: Path = arguments.out or path.with_suffix(".png")
    if out.suffix.lower().lstrip(".") not in IMAGE_FORMATS:
        raise CliError(f"{out}: name the image with the ending of its format: "
                       f"{', '.join('.' + f for f in IMAGE_FORMATS)}")
    check_output(str(out), True, path)  # plot replaces its image, never its input
    from hexactl.adapters.files.recording_file import RecordingReadError, read_recording, read_side_file

    try:
        header, columns, cut_line = read_recording(path)
        side = read_side_file(path)
    except RecordingReadError as error:
        raise CliError(str(error)) from None
    if cut_line is not None:
        print(f"{path}: line {cut_line} was cut (an interrupted recording?): left out", file=sys.stderr)
    if isinstance(side, dict) and isinstance(side.get("columns"), list) and [
            column.get("name") if isinstance(column, dict) else None for column in side["columns"]] != header:
        print(f"{path}: its side file {path.with_suffix('.json')} describes other columns (another recording's?): "
              "plotted without it", file=sys.stderr)
        side = None
    time_s = columns[header.index("t_s")]
    if len(back := (time_s[1:] < time_s[:-1]).nonzero()[0]):
        print(f"{path}: t_s goes back at row {int(back[0]) + 2} of its values (a recording's never does: edited?): "
              "plotted as it is", file=sys.stderr)
    import matplotlib  # heavy: only for plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(title, [name for name in header if name.startswith(prefix)]) for prefix, title in _GROUPS]
    panels = [(title, names) for title, names in panels if names]
    if not panels:
        raise CliError(f"{path}: no signal columns to plot (only {', '.join(header)})")
    figure, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(10, 2.6 * len(panels)), squeeze=False)
    for axis, (title, names) in zip(axes[:, 0], panels):
        # a pose's mm on the left axis, its degrees on a right one; each legend on its side
        for unit_index, unit in enumerate(dict.fromkeys(name.rsplit("_", 1)[1] for name in names)):
            on_the_right = unit_index > 0
            target = axis.twinx() if on_the_right else axis
            colours = iter(plt.rcParams["axes.prop_cycle"].by_key()["color"][3 * unit_index:])
            for name in (n for n in names if n.endswith(f"_{unit}")):
                target.plot(*envelope(time_s, columns[header.index(name)], PLOT_BUCKETS), linewidth=0.8,
                            color=next(colours), label=name.rsplit("_", 1)[0].split("_")[-1])
            target.set_ylabel(f"{title} ({_UNITS.get(unit, unit)})")
            target.legend(loc="upper right" if on_the_right else "upper left", fontsize="x-small", ncol=3)
        axis.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    figure.suptitle(_title(path, side))
    figure.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(out, dpi=100)
    except OSError as error:
        raise write_failed(out, error) from None
    finally:
        plt.close(figure)
    print(out)
    return EXIT_OK


_UNITS = {"us": "µs", "deg": "°"}


def envelope(time_s: NDArray[np.float64], values: NDArray[np.float64], buckets: int
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``values`` over ``time_s`` as drawn: as they are when there are at most ``2 ×
    buckets``; else each of ``buckets`` runs of samples as its minimum and maximum at the
    run's first time, as a scope draws a long record (every spike stays in the image, whose
    1000 pixels could not show more points anyway). NaN (a cell not recorded) is skipped;
    a run of NaN only stays NaN, a gap in the line."""
    import numpy as np

    if len(values) <= 2 * buckets:
        return time_s, values
    starts = np.linspace(0, len(values), buckets, endpoint=False).astype(np.int64)
    with np.errstate(invalid="ignore"):
        low, high = np.fmin.reduceat(values, starts), np.fmax.reduceat(values, starts)
    return np.repeat(time_s[starts], 2), np.column_stack((low, high)).ravel()


def _title(path: Path, side: dict[str, Any] | None) -> str:
    if not isinstance(side, dict):
        return path.stem
    return (f"{side.get('name', path.stem)}: {side.get('rate_hz', '?')} Hz, frame {side.get('frame', '?')}, "
            f"from {side.get('started_utc') or '?'}, {side.get('rows_written', '?')} rows, ended {side.get('ended', '?')}")
