#!/usr/bin/env python3
"""Run the project's ``vcan``-marked pytest tests inside user-mode Linux.

Why
---
hexactl talks CAN through python-can's SocketCAN backend.  Tests marked
``@pytest.mark.vcan`` need a real ``vcan0`` network interface, which needs the
kernel's ``can``, ``can-raw`` and ``vcan`` modules.  The kernel of our dev/CI
machines has no CAN support at all and we cannot load modules into it.
Debian's ``user-mode-linux`` package ships a Linux kernel that runs as an
ordinary host process (``/usr/bin/linux.uml``) together with those modules
(``/usr/lib/uml/modules/<version>/``).  This tool boots that kernel with the
host's own filesystem as its root (hostfs), creates ``vcan0`` inside it, runs
``python -m pytest -m vcan ...`` there with the *same* interpreter and
checkout as the host, relays the output and exits with pytest's exit code.
No disk image, no network, no root needed at run time (root only to
``apt-get install`` missing packages).

Usage
-----
    python tools/uml_vcan.py [--timeout S] [--mem 1G] [-v] [--keep] [PYTEST ARGS...]
    python tools/uml_vcan.py --direct [PYTEST ARGS...]   # host already has vcan0

Default pytest args: ``tests`` (all vcan-marked tests of the repo).  Options
that belong to this tool must come before the pytest args; use ``--`` to be
explicit (``python tools/uml_vcan.py -- -k filter -x``).  pytest runs from
the repo root (so pyproject's settings apply); arguments that are existing
paths relative to your cwd are made absolute first.

Recipe (what happens)
---------------------
1. Ensure ``linux.uml`` (user-mode-linux), ``insmod`` (kmod), ``ip``
   (iproute2) and ``gcc`` (for the XSAVE shim, see the gotchas) exist; if not, ``apt-get update && apt-get install -y`` them
   (root only; otherwise fail with a clear message, exit 120).
2. Resolve the UML kernel version (``linux.uml --version``) and the ``.ko``
   files for ``can-raw`` and ``vcan`` *with their dependencies* from
   ``modules.dep`` (vcan.ko needs can-dev.ko in Debian's build).
3. Pick a directory for UML's guest-RAM file (see gotchas), write a small
   ``/bin/sh`` init script into a fresh temp dir on a host path the guest can
   see, and boot::

     linux.uml mem=1G root=/dev/root rootfstype=hostfs rootflags=/ rw \
         init=<tmp>/init.sh con=null con0=null,fd:1 ssl=null

   with stdin=/dev/null and stdout/stderr piped to this process.
4. The init script mounts /proc, /sys, a tmpfs on /dev/shm and devpts, brings
   ``lo`` up, insmods the modules, ``ip link add dev vcan0 type vcan; ip link
   set up vcan0``, silences kernel console messages, cds to the repo root,
   exports the relevant host environment plus ``HEXACTL_IN_UML=1`` and runs
   ``<sys.executable> -m pytest -m vcan ARGS`` (interrupted with SIGINT a
   minute before the timeout, so that it still reports its failures; output through ``tee`` so
   pytest sees a pipe, not a tty, and a log lands in the temp dir).  The exit
   code is written to ``<tmp>/exitcode``; finally ``echo o >
   /proc/sysrq-trigger`` powers the guest off and linux.uml exits 0.
5. The host relays everything between the ``PYTEST-BEGIN`` and
   ``PYTEST-END`` markers to stdout, keeps the boot log (printed to stderr
   only on failure or with ``-v``), enforces the timeout (kills the UML
   process group), removes the temp dir and exits with the inner code.

Gotchas found while building this
---------------------------------
* Guest RAM is a file UML creates (O_TMPFILE) in $TMP/$TEMP/$TMPDIR, else
  /dev/shm, else /tmp, mmap()ed with PROT_EXEC.  If that filesystem is too
  small (Docker's default 64M /dev/shm) the guest dies later with "Bus error -
  the host /dev/shm or /tmp mount likely just ran out of space".  We choose a
  writable, non-noexec directory with enough free space and pass it as
  TMPDIR/TMP/TEMP to linux.uml only.
* Console: ``con0=fd:0,fd:1`` logs "epollctl add err fd N, Operation not
  permitted" when stdin/stdout are /dev/null or regular files (they cannot be
  epolled); ``con0=null,fd:1`` never reads stdin, so it works with stdin
  closed or /dev/null (CI), and stdout is always our pipe.
  Output lines arrive with CRLF (tty onlcr); we strip the CR.
* The guest's /dev is devtmpfs without /dev/shm: Python multiprocessing
  (SemLock) fails with FileNotFoundError until a tmpfs is mounted there.
  /tmp is deliberately NOT a tmpfs: with a hostfs root the guest's /tmp is the
  host's /tmp, which is where the result file is written.
* ``poweroff -f`` is a systemctl symlink on Debian and absent in minimal
  containers; the sysrq trigger is kernel-only and makes linux.uml exit 0.
  If init exits instead, the kernel panics and linux.uml aborts (SIGABRT) -
  it does not hang, and the host timeout is the last resort anyway.
* On a host with AVX-512 or AMX (XSAVE state beyond the 832 bytes UML 6.1 keeps per
  task) init dies at once: "userspace - ptrace set fp regs failed, errno = 14", then
  "Kernel panic - not syncing: Attempted to kill init! exitcode=0x0000000b". The host
  kernel takes PTRACE_SETREGSET (NT_X86_XSTATE) only of the whole XSAVE buffer; UML
  sizes it at run time only since 6.13. linux.uml runs with ``tools/uml_xstate.c``
  preloaded (built with the host's gcc), which keeps the rest of each task's state
  beside UML's part and puts them back together: each guest task gets its whole
  state back, AVX-512 registers included. Elsewhere it passes everything through.
* The UML kernel is single-CPU with HZ=100 but high-resolution timers
  (``hres_active``: a 4 ms sleep lasts 5.3 ms median); boot to the pytest start
  takes about 2 s. Each guest system call costs about 28 us (ptrace), and the
  guest's CPU is one host process's share: on a loaded host everything inside
  runs several times slower (``python -c pass`` 0.6 s, importing hexactl's CLI
  14-25 s). Hence precompile() and no PYTHONDONTWRITEBYTECODE in the guest.

Exit codes: the inner pytest's exit code, or
  120 prerequisites missing / could not be installed / unusable host setup
  121 UML failed to boot (died or hung before pytest started)
  122 CAN modules or vcan0 could not be set up inside UML
  123 UML died while pytest was running (no exit code written)
  124 timeout (UML killed)

Python standard library only.
"""

from __future__ import annotations

import argparse
import collections
import os
import queue
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from _debian import SBIN_PATH, PackagesMissing, ensure_executables  # tools/, beside this file

EXIT_PREREQ = 120
EXIT_BOOT = 121
EXIT_VCAN = 122
EXIT_CRASH = 123
EXIT_TIMEOUT = 124

REPO = Path(__file__).resolve().parent.parent
MARK = "@@UML_VCAN@@"
UML_MODULES_ROOT = Path("/usr/lib/uml/modules")
# Modules we want loaded; dependencies come from modules.dep.
WANTED_MODULES = ["can-raw", "vcan"]
# Paths the guest mounts over (its own proc/sys/devtmpfs), so host files
# there are invisible inside the guest.
GUEST_SHADOWED = ("/proc", "/sys", "/dev")
# Host environment variables forwarded to the inner pytest.
ENV_EXACT = {
    "PATH", "HOME", "USER", "LOGNAME", "LANG", "LANGUAGE", "TZ", "TMPDIR",
    "VIRTUAL_ENV", "CONDA_PREFIX", "CONDA_DEFAULT_ENV", "CI", "MPLBACKEND",
    "PYTEST_ADDOPTS", "PYTEST_PLUGINS", "NO_COLOR", "FORCE_COLOR",
}
ENV_PREFIXES = ("LC_", "PYTHON", "PYENV_", "HYPOTHESIS_", "HEXACTL_", "PIP_")


def log(msg: str) -> None:
    print(f"uml_vcan: {msg}", file=sys.stderr, flush=True)


class ToolError(Exception):
    def __init__(self, code: int, msg: str):
        super().__init__(msg)
        self.code = code


# --------------------------------------------------------------------------
# host prerequisites


def build_xstate_shim(gcc: str, work: str) -> str:
    """tools/uml_xstate.c built into ``work``: the library preloaded into linux.uml so
    that it can hand a host's whole XSAVE state back (see the gotcha); its path."""
    shim = os.path.join(work, "uml_xstate.so")
    built = subprocess.run([gcc, "-shared", "-fPIC", "-O2", "-o", shim, str(Path(__file__).with_name("uml_xstate.c")),
                            "-ldl", "-lpthread"], capture_output=True, text=True)
    if built.returncode != 0:
        raise ToolError(EXIT_PREREQ, f"could not build the XSAVE shim for linux.uml:\n{built.stderr}")
    return shim


def ensure_packages() -> dict[str, str]:
    try:
        return ensure_executables({"linux.uml": "user-mode-linux", "insmod": "kmod", "ip": "iproute2", "gcc": "gcc"},
                                  log)
    except PackagesMissing as e:
        raise ToolError(EXIT_PREREQ, str(e))


def uml_version(uml: str) -> str:
    try:
        out = subprocess.run([uml, "--version"], stdin=subprocess.DEVNULL, capture_output=True,
                             text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.TimeoutExpired) as e:
        raise ToolError(EXIT_PREREQ, f"cannot run '{uml} --version': {e}")
    ver = out.splitlines()[-1].strip() if out else ""
    if ver and (UML_MODULES_ROOT / ver).is_dir():
        return ver
    dirs = sorted(p.name for p in UML_MODULES_ROOT.glob("*") if (p / "modules.dep").is_file())
    if len(dirs) == 1:
        return dirs[0]
    raise ToolError(EXIT_PREREQ, f"cannot find UML modules for kernel '{ver}' under {UML_MODULES_ROOT} (found {dirs})")


def module_load_order(moddir: Path, wanted: list[str]) -> list[str]:
    """Absolute .ko paths for ``wanted`` plus dependencies, dependencies first."""
    def norm(name: str) -> str:
        base = name.rsplit("/", 1)[-1]
        base = base.split(".ko", 1)[0]
        return base.replace("_", "-")

    deps: dict[str, tuple[str, list[str]]] = {}
    depfile = moddir / "modules.dep"
    if depfile.is_file():
        for line in depfile.read_text().splitlines():
            if ":" not in line:
                continue
            path, rest = line.split(":", 1)
            deps[norm(path)] = (path, rest.split())
    else:  # no modules.dep: locate files, assume no extra deps beyond can for can-raw
        for ko in moddir.rglob("*.ko*"):
            deps[norm(ko.name)] = (str(ko.relative_to(moddir)), [])
    builtin = set()
    bfile = moddir / "modules.builtin"
    if bfile.is_file():
        builtin = {norm(l) for l in bfile.read_text().split()}

    order: list[str] = []
    seen: set[str] = set()

    def visit(name: str) -> None:
        if name in seen or name in builtin:
            return
        seen.add(name)
        if name not in deps:
            raise ToolError(EXIT_PREREQ, f"kernel module {name} not found in {moddir}")
        path, dlist = deps[name]
        for d in reversed(dlist):  # modules.dep lists deps top-down; load bottom-up
            visit(norm(d))
        order.append(str(moddir / path))

    for w in wanted:
        visit(norm(w))
    return order


def pick_memdir(mem_bytes: int) -> str:
    """A writable, exec-mappable directory with room for the guest RAM file."""
    need = mem_bytes + (128 << 20)
    cands = [os.environ.get(k) for k in ("TMP", "TEMP", "TMPDIR")]
    cands += ["/dev/shm", "/tmp", "/var/tmp", tempfile.gettempdir()]
    report = []
    for d in cands:
        if not d or not os.path.isdir(d):
            continue
        try:
            st = os.statvfs(d)
        except OSError:
            continue
        free = st.f_bavail * st.f_frsize
        if st.f_flag & os.ST_NOEXEC:
            report.append(f"{d}: mounted noexec")
        elif not os.access(d, os.W_OK | os.X_OK):
            report.append(f"{d}: not writable")
        elif free < need:
            report.append(f"{d}: only {free >> 20} MiB free")
        else:
            return d
    raise ToolError(EXIT_PREREQ, "no directory for UML's guest memory file with "
                    f"{need >> 20} MiB free, writable and exec-mappable ({'; '.join(report)}); "
                    "set TMPDIR to one or lower --mem")


def guest_visible(path: str) -> bool:
    p = os.path.realpath(path)
    return not any(p == s or p.startswith(s + "/") for s in GUEST_SHADOWED) and " " not in p


def make_workdir() -> str:
    for base in (tempfile.gettempdir(), "/tmp", "/var/tmp"):
        if os.path.isdir(base) and guest_visible(base) and os.access(base, os.W_OK):
            return tempfile.mkdtemp(prefix="uml_vcan-", dir=base)
    raise ToolError(EXIT_PREREQ, "no temp dir visible to the UML guest (not under /proc, /sys, /dev; no spaces)")


def parse_size(s: str) -> int:
    s = s.strip().upper()
    mult = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    if s and s[-1] in mult:
        return int(float(s[:-1]) * mult[s[-1]])
    return int(s)


# --------------------------------------------------------------------------
# guest init script

INIT_TEMPLATE = r"""#!/bin/sh
# Generated by tools/uml_vcan.py: init (PID 1) of the user-mode Linux guest.
RES=@RES@
PATH=@SBIN@
export PATH
say() { printf '%s %s\n' "@MARK@" "$*"; printf '%s\n' "$*" >> "$RES/status"; }
up() { cut -d' ' -f1 /proc/uptime 2>/dev/null; }
finish() {
    sync
    echo o > /proc/sysrq-trigger   # power off: linux.uml exits 0
    sleep 5
    poweroff -f; halt -f
    exit 0                         # init exits -> kernel panic -> linux.uml aborts
}
fail() { say "FAIL $1 $2"; finish; }

mount -t proc proc /proc || fail BOOT "mount /proc failed"
mount -t sysfs sysfs /sys || fail BOOT "mount /sys failed"
mkdir -p /dev/shm /dev/pts
mount -t tmpfs -o mode=1777 shm /dev/shm || fail BOOT "mount tmpfs on /dev/shm failed"
mount -t devpts -o mode=620,ptmxmode=666 devpts /dev/pts || true
ip link set lo up || true
say "BOOTED $(up)"

for ko in @MODULES@; do
    @INSMOD@ "$ko" || fail VCAN "insmod $ko failed"
done
@IP@ link add dev vcan0 type vcan || fail VCAN "ip link add vcan0 failed"
@IP@ link set up vcan0 || fail VCAN "ip link set up vcan0 failed"
[ -e /sys/class/net/vcan0 ] || fail VCAN "vcan0 missing in /sys/class/net"
say "VCAN-OK"
echo 1 > /proc/sys/kernel/printk   # keep kernel messages out of pytest output

cd @CWD@ || fail BOOT "cd @CWD@ failed"
@ENV@
say "PYTEST-BEGIN $(up)"
# SIGINT before the host's timeout kills the guest: pytest then still reports the failures so far.
{ timeout -s INT -k 30 @INNER_TIMEOUT@ @PYTEST@ </dev/null; echo $? > "$RES/exitcode"; } 2>&1 | tee "$RES/pytest.log"
say "PYTEST-END $(cat "$RES/exitcode" 2>/dev/null) $(up)"
finish
"""


INNER_MARGIN_S = 60.0
"""The inner pytest is interrupted this long before the overall timeout: time for its
report of the failures so far to reach the host on a starved guest."""


def build_init(res: str, modules: list[str], exes: dict[str, str], cwd: str,
               pytest_cmd: list[str], env: dict[str, str], inner_timeout_s: float) -> str:
    q = shlex.quote
    env_lines = "\n".join(f"export {k}={q(v)}" for k, v in sorted(env.items()))
    repl = {
        "@RES@": q(res), "@SBIN@": q(SBIN_PATH), "@MARK@": MARK,
        "@MODULES@": " ".join(q(m) for m in modules), "@INSMOD@": q(exes["insmod"]),
        "@IP@": q(exes["ip"]), "@CWD@": q(cwd), "@ENV@": env_lines,
        "@PYTEST@": " ".join(q(a) for a in pytest_cmd), "@INNER_TIMEOUT@": f"{max(1.0, inner_timeout_s):.0f}",
    }
    text = INIT_TEMPLATE
    for k, v in repl.items():
        text = text.replace(k, v)
    return text


def guest_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k in ENV_EXACT or k.startswith(ENV_PREFIXES)}
    # The guest reads bytecode that precompile() wrote; without it each of its Python
    # processes compiles the project's sources again on the guest's slow CPU.
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.setdefault("PATH", SBIN_PATH)
    env.setdefault("HOME", os.path.expanduser("~"))
    if "TMPDIR" in env and not guest_visible(env["TMPDIR"]):
        env.pop("TMPDIR")
    env["HEXACTL_IN_UML"] = "1"
    env["PYTHONUNBUFFERED"] = "1"
    env["COLUMNS"] = str(shutil.get_terminal_size((100, 24)).columns)
    if sys.stdout.isatty() and "NO_COLOR" not in env:
        env.setdefault("PY_COLORS", "1")
    return env


# --------------------------------------------------------------------------
# running

PRECOMPILED = ("hexactl", "firmware_proto", "tests")
"""The repo's packages compiled to bytecode on the host before the guest boots."""


def precompile() -> None:
    """Write the bytecode of :data:`PRECOMPILED` (``__pycache__``, ignored by git) on the
    host: the guest's one CPU is tens of times slower, and every process the vcan tests
    start there would otherwise compile the same sources again (PYTHONDONTWRITEBYTECODE
    in the environment): importing ``hexactl``'s CLI took 25 s in the guest without
    bytecode and 14 s with it (busy host), CPU taken from the loop and the simulator the
    tests judge."""
    r = subprocess.run([sys.executable, "-m", "compileall", "-q", *PRECOMPILED], cwd=REPO,
                       stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        raise ToolError(EXIT_PREREQ, f"compiling the repo's sources failed (fix the syntax error):\n{r.stdout}{r.stderr}")



def _reader(stream, q: queue.Queue) -> None:
    for raw in iter(stream.readline, b""):
        q.put(raw.decode("utf-8", "replace").rstrip("\r\n").rstrip("\r"))
    q.put(None)


def _kill_group(proc: subprocess.Popen) -> None:
    """Kill the UML process group (linux.uml forks helper processes)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _exited_unreaped(pid: int) -> bool:
    # WNOWAIT: the leader stays a zombie, so its pid/pgid cannot be reused
    # before we have killed the rest of its group.
    try:
        info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:
        return True
    return info is not None


def run_uml(args: argparse.Namespace, pytest_args: list[str]) -> int:
    t_start = time.monotonic()
    exes = ensure_packages()
    ver = uml_version(exes["linux.uml"])
    modules = module_load_order(UML_MODULES_ROOT / ver, WANTED_MODULES)
    mem_bytes = parse_size(args.mem)
    memdir = pick_memdir(mem_bytes)
    cwd = str(REPO)
    if not guest_visible(cwd):
        raise ToolError(EXIT_PREREQ, f"repo {cwd} is not visible inside the guest (under /proc, /sys or /dev?)")
    if not guest_visible(sys.executable):
        raise ToolError(EXIT_PREREQ, f"interpreter {sys.executable} is not visible inside the guest")

    precompile()
    work = make_workdir()
    try:
        init = os.path.join(work, "init.sh")
        pytest_cmd = [sys.executable, "-m", "pytest", "-m", "vcan", *pytest_args]
        with open(init, "w") as f:
            f.write(build_init(work, modules, exes, cwd, pytest_cmd, guest_env(), args.timeout - INNER_MARGIN_S))
        os.chmod(init, 0o755)
        cmdline = [exes["linux.uml"], f"mem={mem_bytes >> 20}M", "root=/dev/root",
                   "rootfstype=hostfs", "rootflags=/", "rw", f"init={init}",
                   "con=null", "con0=null,fd:1", "ssl=null"]
        uml_env = dict(os.environ, TMPDIR=memdir, TMP=memdir, TEMP=memdir,
                       LD_PRELOAD=build_xstate_shim(exes["gcc"], work))
        log(f"booting UML {ver} (mem {args.mem}, RAM file in {memdir}, timeout {args.timeout:g} s); "
            f"inner: pytest -m vcan {' '.join(pytest_args)}")
        if args.verbose:
            log("command: " + " ".join(shlex.quote(c) for c in cmdline))
        return _supervise(args, cmdline, uml_env, work, t_start)
    finally:
        if args.keep:
            log(f"kept temp dir {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


def _supervise(args, cmdline, uml_env, work, t_start) -> int:
    t_boot = time.monotonic()
    try:
        proc = subprocess.Popen(cmdline, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, env=uml_env, cwd="/",
                                start_new_session=True)
    except OSError as e:
        raise ToolError(EXIT_BOOT, f"cannot start {cmdline[0]}: {e}")
    q: queue.Queue = queue.Queue()
    threading.Thread(target=_reader, args=(proc.stdout, q), daemon=True).start()

    boot_log: collections.deque[str] = collections.deque(maxlen=400)
    st = {"state": "boot", "failure": None, "t_begin": None, "t_end": None, "uptime": "?"}

    def handle(line: str) -> None:
        if line.startswith(MARK):
            word = line[len(MARK):].split() or ["?"]
            if args.verbose:
                log("guest: " + " ".join(word))
            if word[0] == "PYTEST-BEGIN":
                st.update(state="pytest", t_begin=time.monotonic(),
                          uptime=word[1] if len(word) > 1 else "?")
            elif word[0] == "PYTEST-END":
                st.update(state="done", t_end=time.monotonic())
            elif word[0] == "FAIL":
                st["failure"] = (word[1] if len(word) > 1 else "BOOT", " ".join(word[2:]))
            boot_log.append(line)
        elif st["state"] == "pytest":
            sys.stdout.write(line + "\n")
            sys.stdout.flush()
        else:
            boot_log.append(line)
            if args.verbose:
                print(f"[uml] {line}", file=sys.stderr, flush=True)

    deadline = t_boot + args.timeout
    boot_deadline = t_boot + min(args.boot_timeout, args.timeout)
    timed_out = None
    exited_at = None
    try:
        while True:
            now = time.monotonic()
            limit = boot_deadline if st["state"] == "boot" else deadline
            if now >= limit:
                timed_out = "boot" if st["state"] == "boot" else "run"
                break
            # linux.uml gone: stop after a short drain even if a stray helper
            # process still holds the pipe open (then no EOF comes).
            if exited_at is None and _exited_unreaped(proc.pid):
                exited_at = now
            if exited_at is not None and now - exited_at > 2.0:
                break
            try:
                line = q.get(timeout=max(0.01, min(0.2, limit - now)))
            except queue.Empty:
                continue
            if line is None:  # EOF
                break
            handle(line)
        # after PYTEST-END the guest powers off at once; give it a moment
        grace = time.monotonic() + (20 if timed_out is None else 0)
        while not _exited_unreaped(proc.pid) and time.monotonic() < grace:
            time.sleep(0.05)
    finally:
        _kill_group(proc)  # kills stray helper processes of UML, if any
        proc.wait()
    while True:  # lines the reader got before EOF/kill
        try:
            line = q.get(timeout=0.5)
        except queue.Empty:
            break
        if line is None:
            break
        handle(line)
    sys.stdout.flush()
    failure, t_begin, t_end, guest_begin_uptime = st["failure"], st["t_begin"], st["t_end"], st["uptime"]

    t_done = time.monotonic()
    rc_file = os.path.join(work, "exitcode")
    inner_rc = None
    try:
        with open(rc_file) as f:
            inner_rc = int(f.read().strip())
    except (OSError, ValueError):
        pass

    def dump_boot_log():
        log(f"---- last {len(boot_log)} lines of the UML console ----")
        for l in boot_log:
            print(f"[uml] {l}", file=sys.stderr)
        log("---- end of UML console ----")

    timing = []
    if t_begin is not None:
        timing.append(f"boot-to-pytest {t_begin - t_boot:.1f} s (guest uptime {guest_begin_uptime} s)")
    if t_begin is not None and t_end is not None:
        timing.append(f"inner pytest {t_end - t_begin:.1f} s")
    timing.append(f"UML wall {t_done - t_boot:.1f} s, total {t_done - t_start:.1f} s")

    if timed_out:
        if not args.verbose:
            dump_boot_log()
        what = "boot (pytest never started)" if timed_out == "boot" else "the run"
        lim = min(args.boot_timeout, args.timeout) if timed_out == "boot" else args.timeout
        log(f"ERROR: timeout after {lim:g} s during {what}; UML killed. " + "; ".join(timing))
        return EXIT_TIMEOUT
    if failure is not None:
        if not args.verbose:
            dump_boot_log()
        kind, msg = failure
        code = EXIT_VCAN if kind == "VCAN" else EXIT_BOOT
        what = "CAN/vcan0 setup" if kind == "VCAN" else "guest setup"
        log(f"ERROR: {what} failed inside UML: {msg} (exit {code})")
        return code
    if t_begin is None:
        if not args.verbose:
            dump_boot_log()
        log(f"ERROR: UML failed to boot: exited with {proc.returncode} before pytest started (exit {EXIT_BOOT})")
        return EXIT_BOOT
    if inner_rc is None:
        if not args.verbose:
            dump_boot_log()
        log(f"ERROR: UML died while pytest was running (linux.uml exit {proc.returncode}, no exit code written) "
            f"(exit {EXIT_CRASH})")
        return EXIT_CRASH
    if proc.returncode != 0 and args.verbose:
        log(f"note: linux.uml exited with {proc.returncode} after pytest finished")
    log(f"inner pytest exit code {inner_rc}; " + "; ".join(timing))
    return inner_rc


def run_direct(pytest_args: list[str]) -> int:
    if not os.path.exists("/sys/class/net/vcan0"):
        raise ToolError(EXIT_PREREQ, "--direct needs vcan0 on this host: sudo modprobe vcan && "
                        "sudo ip link add dev vcan0 type vcan && sudo ip link set up vcan0")
    cmd = [sys.executable, "-m", "pytest", "-m", "vcan", *pytest_args]
    log("running on the host: " + " ".join(shlex.quote(c) for c in cmd))
    return subprocess.run(cmd, cwd=REPO, stdin=subprocess.DEVNULL).returncode


# pytest options whose separate value is never a path (``-k vcan`` stays as is)
NON_PATH_VALUE_OPTS = {"-k", "-m", "-p", "-o", "-W", "-r", "--tb", "--maxfail", "--durations",
                       "--color", "--log-level", "--import-mode", "--capture"}


def absolutize(arg: str) -> str:
    """``tests/x.py::t`` relative to the host cwd -> absolute (pytest runs from the repo root)."""
    if arg.startswith("-"):
        return arg
    path, sep, rest = arg.partition("::")
    if path and not os.path.isabs(path) and os.path.exists(path):
        return os.path.abspath(path) + sep + rest
    return arg


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="uml_vcan.py",
        description="Run the vcan-marked pytest tests inside user-mode Linux (see module docstring).")
    p.add_argument("--direct", action="store_true",
                   help="host already has vcan0: run pytest -m vcan here, no UML")
    p.add_argument("--timeout", type=float,
                   default=float(os.environ.get("HEXACTL_UML_TIMEOUT", "600")),
                   help="overall timeout in seconds for the UML run (default 600, env HEXACTL_UML_TIMEOUT)")
    p.add_argument("--boot-timeout", type=float, default=120.0,
                   help="seconds until pytest must have started inside UML (default 120)")
    p.add_argument("--mem", default=os.environ.get("HEXACTL_UML_MEM", "1G"),
                   help="guest RAM (default 1G, env HEXACTL_UML_MEM)")
    p.add_argument("-v", "--verbose", action="store_true", help="show the UML console while booting")
    p.add_argument("--keep", action="store_true", help="keep the temp dir (init.sh, pytest.log, exitcode)")
    p.epilog = ("Everything from the first argument that is not one of these options "
                "(or after '--') is passed to the inner pytest; default: tests.")
    argv = list(sys.argv[1:] if argv is None else argv)
    # Our options must come first; the rest belongs to pytest (which has
    # options argparse would otherwise reject or swallow, e.g. -k EXPR).
    flags = {"--direct", "-v", "--verbose", "--keep", "-h", "--help"}
    valued = {"--timeout", "--boot-timeout", "--mem"}
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--":
            break
        if a in flags or a.split("=", 1)[0] in valued and "=" in a:
            i += 1
        elif a in valued:
            i += 2
        else:
            break
    args = p.parse_args(argv[:i])
    pytest_args = argv[i:]
    if pytest_args[:1] == ["--"]:
        pytest_args = pytest_args[1:]
    pytest_args = [a if prev in NON_PATH_VALUE_OPTS else absolutize(a)
                   for prev, a in zip([""] + pytest_args, pytest_args)] or ["tests"]
    try:
        if args.direct:
            return run_direct(pytest_args)
        if os.environ.get("HEXACTL_IN_UML") == "1":
            raise ToolError(EXIT_PREREQ, "already inside the UML guest (HEXACTL_IN_UML=1); use --direct")
        return run_uml(args, pytest_args)
    except ToolError as e:
        log(f"ERROR: {e} (exit {e.code})")
        return e.code
    except KeyboardInterrupt:
        log("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
