"""Make sure the Debian packages a tool needs are installed: apt-get when missing.

Shared by the tools that run host programs (tools/uml_vcan.py: user-mode Linux;
tools/bench_service.py: cyclictest). Python standard library only.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager

SBIN_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
"""Searched besides $PATH: a non-root $PATH often lacks the sbin directories."""

APT_LOCK_TIMEOUT_S = 300
"""How long apt-get waits for another apt/dpkg (another engineer's install) to finish."""

INSTALL_LOCK = "/run/lock/hexactl-apt-get.lock"
"""Held while a tool installs (root only: it alone installs). Two test runs at once on a
machine without the packages both ran apt-get update, and the second failed at once: the
lock of apt's lists is not one DPkg::Lock::Timeout waits for."""


class PackagesMissing(Exception):
    """The packages are missing and cannot be installed here; the message says what to run."""


def which(name: str) -> str | None:
    """``name``'s path on $PATH or the sbin directories, or None."""
    return shutil.which(name, path=os.environ.get("PATH", "") + ":" + SBIN_PATH)


def ensure_executables(need: Mapping[str, str], log: Callable[[str], None],
                       files: Mapping[str, str] | None = None) -> dict[str, str]:
    """Paths of the executables ``need`` maps to their Debian packages, installing the
    packages of the missing ones first (``apt-get update`` then ``install``, output on
    stderr; root only). ``files`` maps other files needed (absolute paths: a font) to
    their packages, installed the same way when missing.

    :raises PackagesMissing: not root, no apt-get, apt-get failed, or still missing after
    """
    def still_missing() -> list[str]:
        return sorted({package for executable, package in need.items() if not which(executable)}
                      | {package for path, package in (files or {}).items() if not os.path.exists(path)})

    missing = still_missing()
    if missing:
        command = "apt-get update && apt-get install -y " + " ".join(missing)
        if not which("apt-get"):
            raise PackagesMissing(f"missing {missing} and no apt-get here; install them with your package manager")
        if os.geteuid() != 0:
            raise PackagesMissing(f"missing Debian packages {missing}; run as root: {command}")
        with _installing(log):
            missing = still_missing()  # another run may have installed them meanwhile
            if missing:
                _install(missing, log)
    found = {executable: which(executable) for executable in need}
    still = [executable for executable, path in found.items() if path is None]
    if still:
        raise PackagesMissing(f"after apt-get install still missing: {still}")
    return found  # type: ignore[return-value]  # no None left


@contextmanager
def _installing(log: Callable[[str], None]) -> Iterator[None]:
    """:data:`INSTALL_LOCK` held, once another tool's install is over."""
    with open(INSTALL_LOCK, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            log(f"waiting for another tool's install of Debian packages to finish ({INSTALL_LOCK}) ...")
            fcntl.flock(lock, fcntl.LOCK_EX)
        yield  # released when the file closes


def _install(missing: list[str], log: Callable[[str], None]) -> None:
    log(f"installing missing Debian packages {' '.join(missing)} (apt-get, output on stderr) ...")
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    apt = ["apt-get", "-q", "-o", f"DPkg::Lock::Timeout={APT_LOCK_TIMEOUT_S}"]
    for step in (apt + ["update"], apt + ["install", "-y", "--no-install-recommends", *missing]):
        completed = subprocess.run(step, stdin=subprocess.DEVNULL, stdout=sys.stderr, stderr=sys.stderr, env=env)
        if completed.returncode != 0:
            raise PackagesMissing(f"'{' '.join(step)}' failed with exit code {completed.returncode}; "
                                  f"cannot install {missing}")
