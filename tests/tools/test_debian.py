"""tools/_debian.py: the packages a tool needs, installed once when two test runs at once
both find them missing."""

from __future__ import annotations

import fcntl
import subprocess
import threading
from types import SimpleNamespace

from tools import _debian
from tools.serving import HANG_S, wait_until


def test_a_package_another_run_installs_meanwhile_is_not_installed_again(tmp_path, monkeypatch) -> None:
    """The second run waits for the first's install, then finds the package there. It ran
    apt-get update beside the first, which failed at once: the lock of apt's lists is not
    one DPkg::Lock::Timeout waits for ("Could not get lock /var/lib/apt/lists/lock")."""
    lock = tmp_path / "apt-get.lock"
    monkeypatch.setattr(_debian, "INSTALL_LOCK", str(lock))
    installed: set[str] = set()
    monkeypatch.setattr(_debian, "which", lambda name: f"/usr/bin/{name}" if name == "apt-get" or name in installed
                        else None)
    monkeypatch.setattr(_debian.os, "geteuid", lambda: 0)
    ran: list[list[str]] = []
    monkeypatch.setattr(_debian, "subprocess", SimpleNamespace(
        DEVNULL=subprocess.DEVNULL, run=lambda step, **_: ran.append(step) or subprocess.CompletedProcess(step, 0)))
    logged: list[str] = []
    found: list[dict[str, str]] = []
    with open(lock, "a") as other:  # another run's install under way
        fcntl.flock(other, fcntl.LOCK_EX)
        second = threading.Thread(target=lambda: found.append(_debian.ensure_executables({"tmux": "tmux"}, logged.append)))
        second.start()
        wait_until(lambda: logged, "the second run to say it waits", HANG_S)
        installed.add("tmux")  # the first run's install is done
    second.join(HANG_S)
    assert found == [{"tmux": "/usr/bin/tmux"}] and ran == [], (found, ran, logged)
