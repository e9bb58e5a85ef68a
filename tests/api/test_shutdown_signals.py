"""``hexactl serve``'s main thread sees SIGINT/SIGTERM wherever the signal lands.

CI once saw the service log "SIGTERM: shutting down" and then hang for good: the handler
set a ``threading.Event`` while the main thread, interrupted inside ``Event.wait``, held
the lock ``set()`` needed (python/cpython#126434). The probe below delivers the signal at
every line the wait runs; the old way deadlocks at the first line that holds the lock.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from hexactl.application.service import ShutdownSignals

ROOT = Path(__file__).resolve().parents[2]

HANG_S = 120.0
"""A probe still running after this long is deadlocked (it takes well under a second)."""

PROBE = textwrap.dedent(
    """
    import os, signal, sys
    from hexactl.application.service import ShutdownSignals

    def lines_run_by(call, *arguments):
        seen = []
        def tracer(frame, event, arg):
            if event == "line":
                seen.append((frame.f_code.co_filename, frame.f_lineno))
            return tracer
        sys.settrace(tracer)
        call(*arguments)
        sys.settrace(None)
        return list(dict.fromkeys(seen))

    with ShutdownSignals() as signals:
        positions = lines_run_by(signals.wait, 0.0)
    for position in positions:
        with ShutdownSignals() as signals:
            sent = []
            def tracer(frame, event, arg):
                if event == "line" and not sent and (frame.f_code.co_filename, frame.f_lineno) == position:
                    sent.append(position)
                    os.kill(os.getpid(), signal.SIGTERM)
                return tracer
            sys.settrace(tracer)
            received = signals.wait(0.0)  # whatever it waits for, the signal is already sent
            sys.settrace(None)
            assert sent and received == signal.SIGTERM, (position, sent, received)
    print(len(positions))
    """
)


def test_a_signal_at_any_line_of_the_wait_is_received() -> None:
    # SIGKILL at the time-out: a deadlocked probe would never act on SIGTERM.
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    probe = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, env=environment, capture_output=True, text=True,
                           timeout=HANG_S)
    assert probe.returncode == 0, probe.stderr
    assert int(probe.stdout) >= 3, probe.stdout  # the wait's own lines at least


def test_a_signal_before_the_wait_is_returned_and_the_handlers_are_restored() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with ShutdownSignals() as signals:
        assert signals.wait(0.0) is None
        os.kill(os.getpid(), signal.SIGINT)
        assert signals.wait(60.0) == signal.SIGINT
        assert signals.wait(0.0) == signal.SIGINT  # the first one stays the answer
    assert signal.getsignal(signal.SIGTERM) is before
    assert signal.set_wakeup_fd(-1) == -1  # no wake-up descriptor left behind


WAIT_IN_THE_MAIN_THREAD = textwrap.dedent(
    """
    import os, signal, threading
    from hexactl.application.service import ShutdownSignals

    with ShutdownSignals() as signals:
        threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGTERM)).start()
        print(signals.wait(3600.0))  # longer than any scheduling delay: it ends on the signal
    """
)


def test_a_signal_during_the_wait_ends_it() -> None:
    """The wait's own bound is an hour: it returns with the signal because the signal woke
    it (the subprocess's time-out only turns a hang into a failure). In a main thread, as
    ``hexactl serve`` waits: from another thread the wait could wake on the descriptor
    before the main thread had run the Python handler, and return None (seen in a run)."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    waited = subprocess.run([sys.executable, "-c", WAIT_IN_THE_MAIN_THREAD], cwd=ROOT, env=environment,
                            capture_output=True, text=True, timeout=HANG_S)
    assert (waited.returncode, waited.stdout.strip()) == (0, str(signal.SIGTERM)), waited.stderr
