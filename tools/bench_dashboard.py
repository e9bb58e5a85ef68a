#!/usr/bin/env python3
"""Benchmark the dashboard: the end-to-end latency from a telemetry record to its drawing
in a real browser, and the control loop with and without a dashboard attached, in one run
beside cyclictest.

    python3 tools/bench_dashboard.py                 # 30 s per phase
    python3 tools/bench_dashboard.py --seconds 10 --json out.json

One ``hexactl serve`` (the built-in simulator; real-time as the process may) plays the
built-in X sweep over and over, so that every record changes what is drawn. Two phases of
``--seconds`` each:

1. **without** a dashboard;
2. ``hexactl dashboard`` **served**, subscribed to the telemetry, no page open;
3. **with** a headless Chromium (Debian's, software WebGL) on its page, drawing the 3D
   view and the plots, on this same machine.

In each phase ``cyclictest`` (one thread at the loop's period, SCHED_FIFO at the loop's
priority) measures what this machine's scheduler gives at the same time, and the loop's
own statistics give its missed cycles (counted over the phase) and its lateness and
compute percentiles (the service's stats window, which the phase fits in).

The latency is the page's own measure of each record it draws: the record's age when the
dashboard received it (the service's monotonic clock is this host's) plus the time from
then to the end of the animation frame that drew it. It includes the PUB/SUB hop, the
dashboard's WebSocket, the page's parsing and the three.js and uPlot drawing.

``--idle-pages N [N …]`` measures something else: a new page's E-stop round trip while N
other pages are connected and do nothing (an outside report: 0.6–0.9 s behind 400 idle
pages on a loaded host).

    python3 tools/bench_dashboard.py --idle-pages 0 100 400
    python3 tools/bench_dashboard.py --idle-pages 400 --stalled   # pages that never read

``--flood N`` measures a page that floods instead: it sends N ``estop`` commands as fast
as the dashboard takes them and reads none of the replies (a wedged or hostile client;
``estop`` is never answered ``busy``). While it does, ``--estops`` fresh pages time their
E-stop as above; the table adds the dashboard's resident memory before and at its peak.

    python3 tools/bench_dashboard.py --flood 300000

``--slow-page MS`` measures a page that handles telemetry more slowly than it comes, as a
browser starved of the CPU does: each telemetry message takes it MS more for ``--seconds``.
Per 2 s, the records the page handled (50 a second come), how far behind the dashboard
the page was (the longest time from the dashboard's receipt of a record to the page done
with it), on how many the page showed no live data, and on how many it showed live data
although over 2 s behind.

    python3 tools/bench_dashboard.py --slow-page 30 --seconds 20

``--silent N`` measures connections that send nothing: a child process opens N TCP
connections to the dashboard and sends no request on them (a stuck script, a tunnel whose
far end vanished, a local process doing it on purpose). Meanwhile ``--estops`` fresh pages
time their E-stop as above; the table adds the dashboard's open file descriptors once
the N are open and at the end, and how many of the N it had closed.

    python3 tools/bench_dashboard.py --silent 5000

For each N, a child process opens N WebSockets on ``/ws`` and keeps them as a browser tab
left open would: it offers permessage-deflate as browsers do, reads every message (and
throws it away), acknowledges every 8th telemetry message as the page does, and answers
the server's pings; with ``--stalled`` it reads nothing (a frozen tab, a wedged client).
Then ``--estops`` times, a fresh page connects, waits for its first message, sends
``estop`` and times the reply. The table gives p50, p95 and max, the dashboard process's
CPU over the phase and the load average; the service's own E-stop round trip through its
API, without the dashboard, comes first for reference.
"""

from __future__ import annotations

import argparse
import base64
import json
import multiprocessing
import os
import random
import re
import resource
import selectors
import socket
import statistics
import struct
import sys
import tempfile
import threading
import time
from urllib.parse import urlsplit
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from _debian import ensure_executables  # noqa: E402
from bench_service import Cyclictest, load_average  # noqa: E402

from hexactl.adapters.api.client import CommandError, HexactlClient  # noqa: E402
from hexactl.control.realtime import DEFAULT_FIFO_PRIORITY  # noqa: E402
from tools.browser import PAGE_STALE_MS, SLOWED_TELEMETRY, dashboard, headless_chromium, page_constant  # noqa: E402
from tools.serving import LOOPBACK, serve, wait_for_tool as wait_for  # noqa: E402

RATE_HZ = 500
WAIT_S = 60.0



def keep_moving(client: HexactlClient) -> int:
    """Play the X sweep again if it ended; a fault latched meanwhile (a loaded host stalls
    the simulated actuators past their watchdog) is reset and counted: returns 1 then."""
    record = client.call("status")["status"]
    if record["state"] == "estop":
        raise SystemExit(f"the controller is in estop: {record['faults']}")
    if record["state"] == "fault":
        print(f"fault latched, reset: {record['faults']}", file=sys.stderr)
        client.call("reset")
        wait_for(lambda: client.call("status")["status"]["state"] == "disabled", "reset")
        client.call("enable")
        wait_for(lambda: client.call("status")["status"]["state"] == "enabled", "enabled")
        return 1
    if record["sequence"] is None:
        try:
            client.call("play", sequence="x_sweep")
        except CommandError as error:
            if error.code not in ("busy", "latched"):  # latched between status and play: reset next time
                raise
    return 0


def phase(client: HexactlClient, seconds: float, workdir: Path, name: str, cyclictest_path: str) -> dict[str, Any]:
    """The loop's figures over ``seconds`` of motion, cyclictest beside it."""
    cyclictest = Cyclictest(cyclictest_path, round(1e6 / RATE_HZ), int(seconds), DEFAULT_FIFO_PRIORITY,
                            workdir / f"cyclictest-{name}.json")
    start = client.call("status")["status"]["loop"]
    load_start = load_average()
    cyclictest.start()
    end_at = time.monotonic() + seconds
    faults = 0
    while time.monotonic() < end_at:
        faults += keep_moving(client)
        time.sleep(0.5)
    loop = client.call("status")["status"]["loop"]
    reference = cyclictest.result(WAIT_S)
    return {"phase": name, "cycles": loop["cycles"] - start["cycles"], "missed": loop["missed"] - start["missed"],
            "lateness_p50_us": loop["lateness_us"]["p50"], "lateness_p99_us": loop["lateness_us"]["p99"],
            "compute_p50_us": loop["compute_us"]["p50"], "compute_p99_us": loop["compute_us"]["p99"],
            "cyclictest_p50_us": reference["p50_us"], "cyclictest_p99_us": reference["p99_us"],
            "faults": faults, "load_start": load_start, "load_end": load_average()}


def _figure(value: float | int | None) -> str:
    """A table cell: counts as they are, µs to 0.1 below 10 and whole above."""
    if value is None or isinstance(value, int):
        return str(value)
    return f"{value:.1f}" if abs(value) < 10 else f"{value:.0f}"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q / 100.0 * len(ordered)))]


# -- a new page's E-stop while other pages idle ----------------------------------------

ESTOP_GAP_S = (0.1, 0.3)
"""Pause between two E-stops, drawn at random so that they do not lock to telemetry's period."""


def open_page(host: str, port: int) -> tuple[socket.socket, bytes]:
    """A WebSocket on ``/ws`` opened as a browser does (permessage-deflate offered), and the
    bytes that came after the handshake's response."""
    sock = socket.create_connection((host, port), timeout=WAIT_S)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                  "Sec-WebSocket-Extensions: permessage-deflate; client_max_window_bits\r\n\r\n").encode())
    received = b""
    while b"\r\n\r\n" not in received:
        chunk = sock.recv(4096)
        if not chunk:
            raise SystemExit(f"the dashboard closed a WebSocket during its handshake: {received[:200]!r}")
        received += chunk
    head, _, rest = received.partition(b"\r\n\r\n")
    if not head.startswith(b"HTTP/1.1 101"):
        raise SystemExit(f"the dashboard refused a WebSocket: {head[:200]!r}")
    return sock, rest


def _frames(buffer: bytearray) -> list[tuple[int, bytes]]:
    """The whole frames at the start of ``buffer`` (removed from it): (opcode, payload of a
    control frame, else its first :data:`HEAD_BYTES`)."""
    frames = []
    while len(buffer) >= 2:
        opcode, length, start = buffer[0] & 0x0F, buffer[1] & 0x7F, 2
        if length == 126:
            if len(buffer) < 4:
                break
            length, start = struct.unpack_from("!H", buffer, 2)[0], 4
        elif length == 127:
            if len(buffer) < 10:
                break
            length, start = struct.unpack_from("!Q", buffer, 2)[0], 10
        if len(buffer) < start + length:
            break
        frames.append((opcode, bytes(buffer[start:start + (length if opcode >= 8 else min(length, HEAD_BYTES))])))
        del buffer[:start + length]
    return frames


HEAD_BYTES = 48
TELEMETRY_HEAD = re.compile(rb'^\{"type": "telemetry", "n": (\d+),')
"""A telemetry message's start, as the dashboard writes it, with its number."""
ACK_EVERY = int(page_constant("ACK_EVERY"))
"""As the page: an acknowledgement every ACK_EVERY-th telemetry message."""


def _acknowledgement(head: bytes, counted: list[int]) -> bytes:
    """The ack frame due after the text frame starting ``head`` (``counted``: the page's
    telemetry messages since its last ack, in a list of one), else b""."""
    if (found := TELEMETRY_HEAD.match(head)) is None:
        if head.startswith(b'{"type": "telemetry"'):  # unacknowledged, the page would stall: say why
            raise SystemExit(f"a telemetry message no longer starts with its number: {head!r}; update TELEMETRY_HEAD")
        return b""
    counted[0] += 1
    if counted[0] < ACK_EVERY:
        return b""
    counted[0] = 0
    return _client_frame(0x1, json.dumps({"type": "ack", "n": int(found[1])}).encode())


def _pong(payload: bytes) -> bytes:
    return _client_frame(0xA, payload)


def _client_frame(opcode: int, payload: bytes) -> bytes:
    """A whole, masked frame as a client sends it (payloads under 64 KiB)."""
    mask = os.urandom(4)
    length = bytes([0x80 | len(payload)]) if len(payload) < 126 else bytes([0x80 | 126]) + struct.pack("!H", len(payload))
    return bytes([0x80 | opcode]) + length + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def flood(url: str, count: int, sent: Any) -> None:
    """In a child process: one page sends ``count`` E-stops as fast as the dashboard reads
    them and reads no reply; ``sent`` counts them. Holds the page open until killed."""
    address = urlsplit(url)
    sock, _ = open_page(address.hostname or "127.0.0.1", address.port or 80)
    sock.settimeout(None)  # blocks while the dashboard reads nothing: that is its back-pressure
    for number in range(count):
        sock.sendall(_client_frame(0x1, json.dumps({"type": "command", "id": number, "cmd": "estop"}).encode()))
        sent.value = number + 1
    threading.Event().wait()


def resident_mb(pid: int) -> float:
    """Process ``pid``'s resident memory, MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def hold_pages(url: str, count: int, stalled: bool, ready: Any, stop: Any, still_open: Any) -> None:
    """In a child process: ``count`` pages on ``url`` held until ``stop`` is set; ``ready``
    set once all are open, ``still_open`` the number not closed by the dashboard at the end.
    A reading page takes every message and answers pings from the start (opening 400 takes
    long enough for the ones opened first to miss a ping otherwise)."""
    address = urlsplit(url)
    selector = selectors.DefaultSelector()
    opened: list[socket.socket] = []
    closed = 0

    def read(timeout_s: float) -> None:
        nonlocal closed
        for key, _ in selector.select(timeout_s):
            try:
                data = key.fileobj.recv(1 << 16)
            except BlockingIOError:
                continue
            except ConnectionError:
                data = b""
            if not data:
                selector.unregister(key.fileobj)
                closed += 1
                continue
            buffer, counted = key.data
            buffer.extend(data)
            for opcode, payload in _frames(buffer):
                if opcode == 0x9:
                    key.fileobj.sendall(_pong(payload))
                elif opcode == 0x1 and (ack := _acknowledgement(payload, counted)):
                    key.fileobj.sendall(ack)

    for _ in range(count):
        sock, rest = open_page(address.hostname or "127.0.0.1", address.port or 80)
        opened.append(sock)
        if not stalled:
            sock.setblocking(False)
            selector.register(sock, selectors.EVENT_READ, (bytearray(rest), [0]))
            read(0.0)
    ready.set()
    while not stop.is_set():
        if stalled:
            stop.wait(0.1)
        else:
            read(0.1)
    if stalled:  # the ones the dashboard closed (a ping unanswered) read as end of file
        closed = sum(1 for sock in opened if _closed(sock))
    still_open.value = count - closed


def _closed(sock: socket.socket) -> bool:
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except ConnectionError:
        return True


def estop_round_trips(url: str, count: int) -> tuple[list[float], int]:
    """``count`` E-stops, each from a fresh page: seconds from sending to its reply, and how
    many replies were errors (an overloaded service's ``loop_timeout``: a reply all the same)."""
    from websockets.sync.client import connect

    socket_url = url.replace("http://", "ws://", 1) + "ws"
    times, errors = [], 0
    for number in range(count):
        with connect(socket_url, open_timeout=WAIT_S, max_size=None) as page:
            page.recv(WAIT_S)  # the link's state: the page is served
            sent = time.perf_counter()
            page.send(json.dumps({"type": "command", "id": number, "cmd": "estop"}))
            while True:
                message = json.loads(page.recv(WAIT_S))
                if message["type"] == "reply" and message["id"] == number:
                    break
            times.append(time.perf_counter() - sent)
            if not message["reply"].get("ok"):
                errors += 1
                print(f"estop: {message['reply']['error']}", file=sys.stderr)
        time.sleep(random.uniform(*ESTOP_GAP_S))
    return times, errors


def cpu_seconds(pid: int) -> float:
    """User and system CPU time of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


OPEN_WAIT_S = 1200.0
"""How long N pages may take to open (a dashboard that serialised each record once per
page took 457 s for 400 on a loaded host: the time is one of the figures)."""


def estop_phase(board_url: str, board_pid: int, pages: int, stalled: bool, count: int) -> dict[str, Any]:
    """``count`` E-stops from fresh pages while ``pages`` others are held open."""
    context = multiprocessing.get_context("spawn")
    ready, stop, still_open = context.Event(), context.Event(), context.Value("i", -1)
    holder = context.Process(target=hold_pages, args=(board_url, pages, stalled, ready, stop, still_open), daemon=True)
    opening = time.monotonic()
    holder.start()
    try:
        if not ready.wait(OPEN_WAIT_S):
            raise SystemExit(f"{pages} pages did not open in {OPEN_WAIT_S:g} s")
        open_s = time.monotonic() - opening
        time.sleep(2.0)  # the last pages' first messages are out
        load_start, cpu_start, started = load_average(), cpu_seconds(board_pid), time.monotonic()
        times, errors = estop_round_trips(board_url, count)
        cpu = (cpu_seconds(board_pid) - cpu_start) / (time.monotonic() - started)
        load_end = load_average()
    finally:
        stop.set()
        holder.join(WAIT_S)
        if holder.is_alive():
            holder.kill()
    return {"pages": pages, "still_open": still_open.value, "stalled": stalled, "open_s": open_s, "errors": errors,
            "round_trips_ms": [t * 1000.0 for t in times], "p50_ms": statistics.median(times) * 1000.0,
            "p95_ms": percentile(times, 95.0) * 1000.0, "max_ms": max(times) * 1000.0, "dashboard_cpu": cpu,
            "load_start": load_start, "load_end": load_end}


def api_round_trips(client: HexactlClient, count: int) -> tuple[list[float], int]:
    """``count`` E-stops straight to the API, on one client: seconds each, and the errors."""
    times, errors = [], 0
    for _ in range(count):
        sent = time.perf_counter()
        reply = client.request("estop")
        times.append(time.perf_counter() - sent)
        errors += not reply.get("ok")
        time.sleep(random.uniform(*ESTOP_GAP_S))
    return times, errors


CONNECT_S = 5.0
"""How long a silent connection may take to open; past it the dashboard is taken as full."""


def hold_silent(url: str, count: int, ready: Any, stop: Any, still_open: Any) -> None:
    """In a child process: ``count`` connections to ``url`` that send nothing, held until
    ``stop`` is set; ``ready`` set once all are open, ``still_open`` the number the
    dashboard had not closed by then."""
    address = urlsplit(url)
    resource.setrlimit(resource.RLIMIT_NOFILE, (resource.getrlimit(resource.RLIMIT_NOFILE)[1],) * 2)
    held = []
    for _ in range(count):
        try:
            sock = socket.create_connection((address.hostname or "127.0.0.1", address.port or 80), timeout=CONNECT_S)
        except OSError as error:  # the dashboard takes no more (its descriptors ran out): hold what is open
            print(f"{len(held)} of {count} silent connections opened: {error!r}", file=sys.stderr)
            break
        sock.setblocking(False)  # so that _closed peeks without waiting
        held.append(sock)
    ready.set()
    stop.wait()
    still_open.value = sum(1 for sock in held if not _closed(sock))


def descriptors(pid: int) -> int:
    """How many file descriptors process ``pid`` has open."""
    return len(os.listdir(f"/proc/{pid}/fd"))


def estop_beside_silent_connections(args: argparse.Namespace) -> int:
    """A new page's E-stop round trip while ``--silent`` N connections send nothing."""
    context = multiprocessing.get_context("spawn")
    ready, stop, still_open = context.Event(), context.Event(), context.Value("i", -1)
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        with serve(Path(directory), "--rate", str(RATE_HZ), api=args.api, telemetry=args.telemetry) as served, \
                dashboard(served.api, served.telemetry, "--http", args.http, "--log-level", "warning") as board:
            pid = board.process.pid
            before = descriptors(pid)
            holder = context.Process(target=hold_silent, args=(board.url, args.silent, ready, stop, still_open),
                                     daemon=True)
            holder.start()
            try:
                if not ready.wait(OPEN_WAIT_S):
                    raise SystemExit(f"{args.silent} connections did not open in {OPEN_WAIT_S:g} s")
                opened = descriptors(pid)
                times, errors, unanswered = [], 0, 0
                for _ in range(args.estops):
                    try:
                        timed, failed = estop_round_trips(board.url, 1)
                    except (OSError, TimeoutError) as error:  # not even connected: the descriptors ran out
                        print(f"estop: {error!r}", file=sys.stderr)
                        unanswered += 1
                        continue
                    times, errors = times + timed, errors + failed
                after = descriptors(pid)
            finally:
                stop.set()
                holder.join(WAIT_S)
                if holder.is_alive():
                    holder.kill()
    ms = [t * 1000.0 for t in times] or [float("nan")]
    figures = {"silent": args.silent, "still_open": still_open.value, "descriptors_before": before,
               "descriptors_opened": opened, "descriptors_after": after, "errors": errors, "unanswered": unanswered,
               "round_trips_ms": ms, "p50_ms": statistics.median(ms), "p95_ms": percentile(ms, 95.0), "max_ms": max(ms)}
    return one_row_table(f"E-stop round trip, {args.estops} from fresh pages, beside {args.silent} connections that "
                         "send nothing:",
                         ["silent connections (still open at the end)",
                          "dashboard descriptors: before, once opened, at the end", "p50 ms", "p95 ms", "max ms",
                          "error replies", "pages that could not connect"],
                         [f"{args.silent} ({still_open.value})", f"{before}, {opened}, {after}",
                          f"{figures['p50_ms']:.1f}", f"{figures['p95_ms']:.1f}", f"{figures['max_ms']:.1f}", f"{errors}",
                          f"{unanswered}"], figures, args.json)


def one_row_table(title: str, columns: list[str], row: list[str], figures: dict[str, Any], json_path: Path | None) -> int:
    """Print ``title`` and a Markdown table of one ``row``; write ``figures`` to ``json_path``
    if given. The tool's exit status, 0."""
    print(f"{title}\n")
    print("| " + " | ".join(columns) + " |")
    print("|" + " --- |" * len(columns))
    print("| " + " | ".join(row) + " |")
    if json_path:
        json_path.write_text(json.dumps(figures, indent=2))
    return 0


SLOW_PAGE_BIN_S = 2.0
AFTER_SLOW_S = 10.0
"""How long the page is followed after its slow spell: what was queued for it shows then."""


def slow_page(args: argparse.Namespace) -> int:
    """The table of a page slowed by ``--slow-page`` MS a telemetry message for ``--seconds``."""
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        with serve(Path(directory), "--rate", str(RATE_HZ), api=args.api, telemetry=args.telemetry) as served, \
                dashboard(served.api, served.telemetry, "--http", args.http, "--log-level", "warning") as board:
            driver = headless_chromium()
            try:
                driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": SLOWED_TELEMETRY})
                driver.get(board.url)
                wait_for(lambda: driver.execute_script("return window.hexactlDashboard.dataLoss") is None,
                         "live data on the page")
                records = round(args.seconds * 1000.0 / args.slow_page)
                started = driver.execute_script(f"const slow = window.hexactlTestSlow; slow.ms = {args.slow_page}; "
                                                f"slow.remaining = {records}; return Date.now()")
                wait_for(lambda: driver.execute_script("return window.hexactlTestSlow.endedAt"), "the slow spell over")
                time.sleep(AFTER_SLOW_S)
                handled = driver.execute_script("return window.hexactlTestSlow.handled")
            finally:
                driver.quit()
    rows = []
    for first in range(0, int(args.seconds + AFTER_SLOW_S), int(SLOW_PAGE_BIN_S)):
        begin, end = started + first * 1000.0, started + (first + SLOW_PAGE_BIN_S) * 1000.0
        spell = [m for m in handled if begin <= m["at"] < end and "done" in m]
        if spell:
            behind = [m["done"] - m["sent_ms"] for m in spell]
            rows.append({"from_s": first, "handled": len(spell), "behind_max_ms": max(behind),
                         "shown_not_live": sum(m["loss"] is not None for m in spell),
                         "live_over_stale": sum(m["loss"] is None and b > PAGE_STALE_MS for m, b in zip(spell, behind))})
    print(f"A page slowed by {args.slow_page:g} ms a telemetry message for {args.seconds:g} s ({records} records), "
          f"then followed {AFTER_SLOW_S:g} s (behind: from the dashboard's receipt to the page done with it):\n")
    print(f"| from s | records handled | behind, max ms | shown not live | shown live over {PAGE_STALE_MS:g} ms behind |")
    print("| --- | --- | --- | --- | --- |")
    for row in rows:
        print(f"| {row['from_s']} | {row['handled']} | {row['behind_max_ms']:.0f} | {row['shown_not_live']} | "
              f"{row['live_over_stale']} |")
    if args.json:
        args.json.write_text(json.dumps({"slow_ms": args.slow_page, "records": records, "bins": rows}, indent=2))
    return 0


def estop_under_idle_pages(args: argparse.Namespace) -> int:
    """The table of a new page's E-stop round trip for each ``--idle-pages`` N, row by row."""
    kind = "stalled (never read)" if args.stalled else "idle (reading)"
    print(f"E-stop round trip, {args.estops} each, from a fresh page while N other pages are {kind}:\n")
    print("| N pages (still open at the end) | opened in s | p50 ms | p95 ms | max ms | error replies | dashboard CPU | "
          "load average (1 min) start → end |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |", flush=True)
    phases = []
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        workdir = Path(directory)
        with serve(workdir, "--rate", str(RATE_HZ), api=args.api, telemetry=args.telemetry) as served, \
                HexactlClient(served.api, timeout_s=30.0) as client:
            times, errors = api_round_trips(client, args.estops)
            api = [t * 1000.0 for t in times]
            print(f"| API alone, no dashboard | | {statistics.median(api):.1f} | {percentile(api, 95.0):.1f} | "
                  f"{max(api):.1f} | {errors} | | |", flush=True)
            with dashboard(served.api, served.telemetry, "--http", args.http, "--log-level", "warning") as board:
                for pages in args.idle_pages:
                    figures = estop_phase(board.url, board.process.pid, pages, args.stalled, args.estops)
                    phases.append(figures)
                    print(f"| {pages} ({figures['still_open']}) | {figures['open_s']:.1f} | {figures['p50_ms']:.1f} | "
                          f"{figures['p95_ms']:.1f} | {figures['max_ms']:.1f} | {figures['errors']} | "
                          f"{figures['dashboard_cpu'] * 100:.0f} % | "
                          f"{figures['load_start'][0]:.2f} → {figures['load_end'][0]:.2f} |", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"api_ms": api, "phases": phases}, indent=2))
    return 0


FLOOD_HEAD_START_S = 2.0
"""How long the flood runs, once its first E-stop is sent, before the first timed one."""


def estop_under_a_flood(args: argparse.Namespace) -> int:
    """A new page's E-stop round trip while another page floods E-stops it never reads."""
    context = multiprocessing.get_context("spawn")
    sent = context.Value("q", 0)
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        with serve(Path(directory), "--rate", str(RATE_HZ), api=args.api, telemetry=args.telemetry) as served, \
                dashboard(served.api, served.telemetry, "--http", args.http, "--log-level", "warning") as board:
            pid = board.process.pid
            rss_start, peak = resident_mb(pid), 0.0
            flooder = context.Process(target=flood, args=(board.url, args.flood, sent), daemon=True)
            flooder.start()
            try:
                load_start, cpu_start, started = load_average(), cpu_seconds(pid), time.monotonic()
                # From its first E-stop, not from its start: a loaded host takes seconds to start a process.
                wait_for(lambda: sent.value > 0, "the flood's first E-stop")
                time.sleep(FLOOD_HEAD_START_S)
                times = []
                for _ in range(args.estops):
                    times += estop_round_trips(board.url, 1)[0]
                    peak = max(peak, resident_mb(pid))
                cpu = (cpu_seconds(pid) - cpu_start) / (time.monotonic() - started)
                load_end = load_average()
            finally:
                flooder.kill()
                flooder.join(WAIT_S)
    ms = [t * 1000.0 for t in times]
    figures = {"flood": args.flood, "sent_by_the_end": sent.value, "round_trips_ms": ms, "p50_ms": statistics.median(ms),
               "p95_ms": percentile(ms, 95.0), "max_ms": max(ms), "rss_start_mb": rss_start, "rss_peak_mb": peak,
               "dashboard_cpu": cpu, "load_start": load_start, "load_end": load_end}
    return one_row_table(f"E-stop round trip, {args.estops} from fresh pages, while one page floods {args.flood} "
                         "E-stops and reads no reply:",
                         ["flood sent by the end", "p50 ms", "p95 ms", "max ms", "dashboard memory, start → peak",
                          "dashboard CPU", "load average (1 min) start → end"],
                         [f"{sent.value} of {args.flood}", f"{figures['p50_ms']:.1f}", f"{figures['p95_ms']:.1f}",
                          f"{figures['max_ms']:.1f}", f"{rss_start:.0f} → {peak:.0f} MB", f"{cpu * 100:.0f} %",
                          f"{load_start[0]:.2f} → {load_end[0]:.2f}"], figures, args.json)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="each phase's length (default 30; at most the "
                        "loop's stats window, 32.8 s at 500 Hz)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    parser.add_argument("--idle-pages", type=int, nargs="+", metavar="N",
                        help="instead: a new page's E-stop round trip with N other pages connected, for each N")
    parser.add_argument("--stalled", action="store_true", help="with --idle-pages: the pages never read")
    parser.add_argument("--flood", type=int, metavar="N", help="instead: a new page's E-stop round trip while another "
                        "page sends N E-stops and reads no reply")
    parser.add_argument("--silent", type=int, metavar="N", help="instead: a new page's E-stop round trip beside N "
                        "connections that send nothing")
    parser.add_argument("--slow-page", type=float, metavar="MS", help="instead: a page that takes MS more for each "
                        "telemetry message for --seconds, and how far behind it falls")
    parser.add_argument("--estops", type=int, default=30, help="with --idle-pages, --flood or --silent: E-stops per "
                        "phase (default 30)")
    parser.add_argument("--api", default=LOOPBACK, help="with --idle-pages, --flood, --silent or --slow-page: the "
                        "service's API endpoint")
    parser.add_argument("--telemetry", default=LOOPBACK, help="with --idle-pages, --flood, --silent or --slow-page: "
                        "its telemetry endpoint")
    parser.add_argument("--http", default="127.0.0.1:0", help="with --idle-pages, --flood, --silent or --slow-page: "
                        "the dashboard's address")
    args = parser.parse_args()
    if args.idle_pages is not None:
        return estop_under_idle_pages(args)
    if args.flood is not None:
        return estop_under_a_flood(args)
    if args.silent is not None:
        return estop_beside_silent_connections(args)
    if args.slow_page is not None:
        if not args.slow_page > 0:
            parser.error(f"--slow-page {args.slow_page:g}: give the milliseconds each record takes the page, > 0")
        return slow_page(args)
    cyclictest_path = ensure_executables({"cyclictest": "rt-tests"}, lambda line: print(line, file=sys.stderr))["cyclictest"]
    with tempfile.TemporaryDirectory(prefix="hexactl-bench-dashboard-") as directory:
        workdir = Path(directory)
        with serve(workdir, "--rate", str(RATE_HZ)) as served, HexactlClient(served.api, timeout_s=30.0) as client:
            client.call("enable")
            wait_for(lambda: client.call("status")["status"]["state"] == "enabled", "enabled")
            keep_moving(client)
            without = phase(client, args.seconds, workdir, "without", cyclictest_path)
            with dashboard(served.api, served.telemetry) as board:
                served_only = phase(client, args.seconds, workdir, "served", cyclictest_path)
                driver = headless_chromium()
                try:
                    driver.get(board.url)
                    wait_for(lambda: driver.execute_script("return document.body.dataset.connected") == "true",
                             "the page connected")
                    before = len(driver.execute_script("return window.hexactlDashboard.latencies()"))
                    attached = phase(client, args.seconds, workdir, "with", cyclictest_path)
                    # The page keeps the last 2000: a phase of ≤ 38 s at 50 records/s fits.
                    latencies = driver.execute_script("return window.hexactlDashboard.latencies()")[before:]
                finally:
                    driver.quit()
    if not latencies:
        raise SystemExit("the page drew no record")
    drawn = {"records_drawn": len(latencies), "latency_p50_ms": statistics.median(latencies),
             "latency_p99_ms": percentile(latencies, 99.0), "latency_max_ms": max(latencies)}
    phases = (without, served_only, attached)
    print("| | without a dashboard | the dashboard, no page open | the dashboard and Chromium on its page |")
    print("| --- | --- | --- | --- |")
    for key, label in (("cycles", "loop cycles"), ("missed", "missed (> T/2 late)"),
                       ("lateness_p50_us", "lateness p50 µs, loop"), ("lateness_p99_us", "lateness p99 µs, loop"),
                       ("cyclictest_p50_us", "cyclictest p50 µs"), ("cyclictest_p99_us", "cyclictest p99 µs"),
                       ("compute_p50_us", "compute p50 µs"), ("compute_p99_us", "compute p99 µs"),
                       ("faults", "faults latched (reset)")):
        print(f"| {label} | " + " | ".join(_figure(figures[key]) for figures in phases) + " |")
    print("| load average (1 min) start → end | " + " | ".join(
        f"{figures['load_start'][0]:.2f} → {figures['load_end'][0]:.2f}" for figures in phases) + " |")
    print(f"\nrecord → drawing: p50 {drawn['latency_p50_ms']:.1f} ms, p99 {drawn['latency_p99_ms']:.1f} ms, "
          f"max {drawn['latency_max_ms']:.1f} ms over {drawn['records_drawn']} records drawn")
    if args.json:
        args.json.write_text(json.dumps({"without": without, "served": served_only, "with": attached, "drawing": drawn},
                                        indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
