"""What the browser tests share: Debian's Chromium and chromedriver driven by Selenium, and
one skip line, naming what to install, when any of the three is missing."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))
                 if p), None)
DRIVER = shutil.which("chromedriver")
CHROME_ARGS = ("--headless=new", "--no-sandbox", "--disable-gpu",
               "--disable-background-networking", "--disable-component-update",
               "--disable-sync", "--no-first-run", "--window-size=1400,950")


def skip_without_browser() -> None:
    """Skip the calling test module, in one line, without Chromium, its driver or Selenium."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        has_selenium = False
    else:
        has_selenium = True
    missing = [name for name, ok in (("chromium", CHROMIUM), ("chromedriver", DRIVER),
                                     ("selenium (pip install -e '.[test]')", has_selenium))
               if not ok]
    if missing:
        pytest.skip("browser tests need " + ", ".join(missing)
                    + " (Debian: apt-get install chromium chromium-driver)",
                    allow_module_level=True)


@contextmanager
def chrome() -> Iterator[Any]:
    """A headless Chromium with a profile of its own, quit and removed at the end."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM or ""
    profile = tempfile.mkdtemp(prefix="servobus-chromium-")
    for arg in (*CHROME_ARGS, f"--user-data-dir={profile}"):
        options.add_argument(arg)
    os.environ.setdefault("SE_OFFLINE", "true")  # never let Selenium fetch a driver
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
