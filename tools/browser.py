"""A real headless Chromium (Debian's ``chromium`` and ``chromium-driver``) driven by
Selenium, and ``hexactl dashboard`` in a process of its own: for the dashboard's tests,
its screenshots (docs/dashboard.md) and its latency benchmark.

The packages are installed with apt-get when missing (root), as the vcan runner installs
user-mode Linux.
"""

from __future__ import annotations

import re
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from tools._debian import ensure_executables
from tools.serving import Logged, hexactl_process

FONT = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"
"""Text in the screenshots needs a font; chromium does not depend on one."""

CHROMIUM_FLAGS = (
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
    # The machine's network is closed: without these Chromium keeps trying to reach Google.
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--disable-quic",
    # WebGL on the CPU: the 3D view renders without a GPU.
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
)

START_TIMEOUT_S = 120.0
"""How long ``hexactl dashboard`` may take to say where it serves (seconds when idle)."""

SCRIPT_TIMEOUT_S = 120.0
"""How long WebDriver lets a script in the page take before it gives up: a hang guard."""

_SERVING = re.compile(r"dashboard on (?P<url>http://\S+/)")

PAGE_SCRIPTS = Path(__file__).resolve().parents[1] / "hexactl" / "adapters" / "web" / "static"


def page_constant(name: str) -> float:
    """The number one of the page's scripts declares as ``const <name> = <number>;``: read
    from static/*.js, so that the tests and benchmarks that emulate or judge a page keep no
    copies of its rules.

    :raises LookupError: no script declares such a number
    """
    declaration = re.compile(rf"^(?:export )?const {re.escape(name)} = (-?[0-9.]+);", re.MULTILINE)
    for script in sorted(PAGE_SCRIPTS.glob("*.js")):
        if found := declaration.search(script.read_text()):
            return float(found[1])
    raise LookupError(f"no script in {PAGE_SCRIPTS} declares a number {name}")


PAGE_STALE_MS = page_constant("STALE_MS")
"""A page with no record for longer, or further behind the records, shows no live data."""

SLOWED_TELEMETRY = """
(() => {
  const Native = window.WebSocket;
  const slow = { ms: 100, remaining: 0, endedAt: null, handled: [] };
  window.hexactlTestSlow = slow;
  window.WebSocket = class extends Native {
    addEventListener(type, listener, options) {
      if (type !== 'message') return super.addEventListener(type, listener, options);
      return super.addEventListener(type, (event) => {
        const message = JSON.parse(event.data);
        if (message.type !== 'telemetry') return listener(event);
        const entry = { n: message.n, sent_ms: message.sent_ms, at: Date.now() };
        slow.handled.push(entry);
        if (slow.remaining > 0) {
          const until = performance.now() + slow.ms;
          while (performance.now() < until) { /* the page's work, slow */ }
          slow.remaining -= 1;
          if (slow.remaining === 0) slow.endedAt = Date.now();
        }
        listener(event);
        entry.done = Date.now();
        entry.loss = window.hexactlDashboard ? window.hexactlDashboard.dataLoss : undefined;
        if (entry.loss !== slow.loss) {
          // what the page showed as its verdict changed (a script from outside is not run
          // while such a page is behind: it waits behind the queued records)
          slow.loss = entry.loss;
          const text = (id) => document.getElementById(id)?.innerText;
          entry.shown = { state: text('state'), age: text('data-age'), banner: text('data-lost') };
        }
      }, options);
    }
  };
})();
"""
"""A script to run before the page's own (``Page.addScriptToEvaluateOnNewDocument``) that
makes the page slow, as a browser starved of the CPU is: while ``hexactlTestSlow.remaining``
is above 0, each telemetry message takes the page ``ms`` more (100 by default).
``endedAt`` is when the last slow one was handled, and ``handled`` lists each telemetry
message's ``n``, ``sent_ms``, when the page began handling it (``at``) and was done
(``done``), and what the page then said it had lost (``loss``, its ``dataLoss``), with what
it showed (``shown``: its state, data age and banner) where that changed; the times are
this host's clock, ms, as the dashboard's ``sent_ms``."""


def ensure_chromium() -> dict[str, str]:
    """Paths of ``chromium`` and ``chromedriver``, installed first if missing."""
    return ensure_executables({"chromium": "chromium", "chromedriver": "chromium-driver"},
                              lambda message: print(message, file=sys.stderr, flush=True), {FONT: "fonts-dejavu-core"})


def headless_chromium(width: int = 1600, height: int = 1000):  # -> selenium.webdriver.Chrome
    """A new headless Chromium with its console log kept (``driver.get_log("browser")``)
    and a fresh profile of its own, removed by ``driver.quit()``; quit it when done."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    paths = ensure_chromium()
    options = webdriver.ChromeOptions()
    options.binary_location = paths["chromium"]
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--window-size={width},{height}")
    # Several MB each: left behind, every test run on a shared machine added hundreds to /tmp.
    profile = tempfile.mkdtemp(prefix="hexactl-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(options=options, service=Service(paths["chromedriver"]))
    except BaseException:
        shutil.rmtree(profile, ignore_errors=True)
        raise
    quit_browser = driver.quit

    def quit_and_remove_the_profile() -> None:
        try:
            quit_browser()  # chromedriver ends Chromium before it answers
        finally:
            shutil.rmtree(profile, ignore_errors=True)

    driver.quit = quit_and_remove_the_profile
    # A hang guard, not a measure: on a host loaded with other work the page's main thread
    # (three.js in software) was seen not to run a one-line script within WebDriver's 30 s.
    driver.set_script_timeout(SCRIPT_TIMEOUT_S)
    return driver


@dataclass
class Dashboard(Logged):
    """A running ``hexactl dashboard``: its process, page and log as it grows."""

    url: str = ""


@contextmanager
def dashboard(api: str, telemetry: str, *options: str) -> Iterator[Dashboard]:
    """``hexactl dashboard`` for the service at ``api``/``telemetry`` on a free loopback
    port, started; stopped (SIGTERM, then killed) on the way out.

    :raises RuntimeError: if it does not say where it serves within :data:`START_TIMEOUT_S`
    """
    with hexactl_process(Dashboard, ["dashboard", "--api", api, "--telemetry", telemetry, "--http", "127.0.0.1:0",
                                     *options], _SERVING, START_TIMEOUT_S, merge_stdout=True,
                         sigterm_grace_s=30) as board:
        yield board


def save_screenshot(driver, path: Path) -> Path:  # noqa: ANN001 - selenium's driver
    path.parent.mkdir(parents=True, exist_ok=True)
    driver.save_screenshot(str(path))
    return path
