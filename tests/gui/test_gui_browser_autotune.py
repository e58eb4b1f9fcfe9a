"""The Tuning tab's "Auto" in a real headless Chromium (Selenium + Debian's chromium-driver):
Auto, the confirmation naming the axis and the distance in mm, Go, the progress, the
before/after table, Revert. Axis x: a virtual DYN232M with a direct load at 10 x the rotor
inertia, 5 mm per revolution. Without Chromium, chromedriver or Selenium the module is
skipped with one line saying which is missing.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator
from typing import Any

import browser_rig
import pytest
import rig
from machine.machine_rig import write_machine

browser_rig.skip_without_browser()

from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]
WAIT = 90.0  # a whole run is about 20 s of wall-clock test moves; generous on a loaded host
MACHINE = """\
name = "tune-cell"

[axes.x]
url = "sim://dyn232?fast=1&load=direct&inertia=10"
id = 1
unit = "mm"
per_rev = 5.0
limits = [-10.0, 300.0]
"""


def wait_until(predicate: Callable[[], Any], *, what: str) -> Any:
    return rig.wait_until(predicate, timeout=WAIT, what=what)


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``servobus gui --machine FILE`` in this process (uvicorn on a thread)."""
    import uvicorn

    from servobus.gui.app import create_app
    from servobus.gui.server import bind, uvicorn_config

    app = create_app(machine=write_machine(tmp_path_factory.mktemp("auto"), MACHINE))
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(uvicorn_config(app))
    loop = asyncio.new_event_loop()
    thread = threading.Thread(
        target=lambda: loop.run_until_complete(server.serve(sockets=[sock])), daemon=True)
    thread.start()
    try:
        wait_until(lambda: server.started, what="the GUI server started")
        yield f"http://127.0.0.1:{sock.getsockname()[1]}/"
    finally:
        server.should_exit = True
        thread.join(timeout=15)
        sock.close()


def text(driver: WebDriver, selector: str) -> str:
    return str(driver.execute_script(
        "return document.querySelector(arguments[0]).textContent", selector))


def visible(driver: WebDriver, selector: str) -> bool:
    return bool(driver.execute_script(
        "return !document.querySelector(arguments[0]).closest('.hidden')", selector))


def test_auto_asks_naming_the_axis_in_mm_then_shows_the_table_and_reverts(url: str) -> None:
    with browser_rig.chrome() as page:
        page.get(url)
        wait_until(lambda: page.execute_script("return document.body.dataset.ready"),
                   what="page ready")
        wait_until(lambda: page.execute_script("return window.servobus.link.open"),
                   what="WebSocket open")
        page.find_element(By.CSS_SELECTOR, '#tabs button[data-tab="tuning"]').click()
        wait_until(lambda: visible(page, "#auto-start"), what="the Auto box")
        assert text(page, "#auto-unit") == "mm"
        distance = page.execute_script("return document.querySelector('#auto-distance').value")
        assert distance == "1.25"  # a quarter turn of a 5 mm per revolution axis
        assert not visible(page, "#auto-save")  # DMM: every write goes to EEPROM
        page.find_element(By.ID, "auto-start").click()
        wait_until(lambda: visible(page, "#auto-go"), what="the confirmation")
        question = text(page, "#auto-question")
        assert "tune axis x" in question and "1.25 mm away" in question
        assert "EEPROM" in text(page, "#auto-note")
        gains_before = text(page, "#gains-table")
        page.find_element(By.ID, "auto-go").click()
        state = "return document.querySelector('#auto-progress').dataset.state"
        wait_until(lambda: page.execute_script(state) == "running", what="the run")
        wait_until(lambda: "test move 1" in text(page, "#auto-progress"), what="the progress")
        wait_until(lambda: page.execute_script(state) != "running", what="the run's end")
        assert "done" in text(page, "#auto-progress"), text(page, "#auto-progress")
        assert page.find_elements(By.CSS_SELECTOR, "#auto-table tr[data-row=after]")
        after = text(page, "#auto-table tr[data-row=after]")
        assert "mm" in after and "%" in after
        assert "EEPROM" in text(page, "#auto-hint")
        wait_until(lambda: text(page, "#gains-table") != gains_before, what="the tuned gains")
        page.find_element(By.ID, "auto-revert").click()
        wait_until(lambda: "reverted" in text(page, "#tuning-msg"), what="the revert")
        wait_until(lambda: text(page, "#gains-table") == gains_before,
                   what="the kept gains back in the table")
