"""tools/browser.py's headless Chromium leaves nothing behind: its profile (several MB)
goes with it, so that test runs on a shared machine do not fill /tmp."""

from __future__ import annotations

from pathlib import Path

from tools.browser import headless_chromium


def test_the_profile_is_removed_when_the_browser_quits() -> None:
    driver = headless_chromium()
    try:
        profile = Path(driver.capabilities["chrome"]["userDataDir"])
        assert profile.name.startswith("hexactl-chromium-") and any(profile.iterdir())
    finally:
        driver.quit()
    assert not profile.exists()
