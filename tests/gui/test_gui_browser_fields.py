"""Numbers typed into the GUI never move a motor by accident (issue 28), in a real headless
Chromium (Selenium + Debian's chromium-driver).

Every motion and tuning field gets ``""``, ``abc``, ``12,5``, ``1e999``, ``-`` and ``fast``,
then each button that reads it is pressed: the field shows its error, and nothing but reads
reaches the wire. The GUI runs in this process (uvicorn on a thread) so that the test hooks
every drive link itself (the Axis trace hook) and sees every packet, not a sample of them.
Without Chromium, chromedriver or Selenium the module is skipped with one line saying which
is missing.
"""

from __future__ import annotations

import asyncio
import re
import threading
from collections.abc import Iterator
from typing import Any

import browser_rig
import pytest
from rig import wait_until

browser_rig.skip_without_browser()

from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.remote.webelement import WebElement  # noqa: E402

pytestmark = [pytest.mark.timeout(180), pytest.mark.slow]

TYPED = ["", "abc", "12,5", "1e999", "-", "fast"]
#: A DYN232M read; every other packet is a command or a write.
READ = re.compile(r": (READ_\w+|GENERAL_READ\b)")
#: Motion fields and the buttons that read them (the jog buttons are held, not clicked).
MOTION = {"jog-rpm": ["jog-plus", "jog-minus"], "move-value": ["move-abs", "move-rel"],
          "turn-rpm": ["turn-run"], "wave-amp": ["wave-start"],
          "wave-hz": ["wave-start"]}
TUNING = {"step-value": ["step-plus", "step-minus"],
          "step-duration": ["step-plus", "step-minus"]}
HELD = {"jog-plus", "jog-minus"}


class Gui:
    """``servobus gui`` on three virtual drives, in this process; ``sent``: every packet
    sent to a drive that is not a read."""

    def __init__(self) -> None:
        import uvicorn

        from servobus.gui.app import create_app
        from servobus.gui.server import bind, uvicorn_config
        from servobus.gui.traffic import describe
        from servobus.transport.base import Direction

        self.app = create_app()
        self.sock = bind("127.0.0.1", 0)
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}/"
        self.server = uvicorn.Server(uvicorn_config(self.app))
        self.loop = asyncio.new_event_loop()
        self.sent: list[str] = []

        def hook(direction: Direction, item: object, t: float) -> None:
            if direction is Direction.TX:
                text = describe(item, direction)[0]
                if not READ.search(text):
                    self.sent.append(text)

        self.thread = threading.Thread(
            target=lambda: self.loop.run_until_complete(self.server.serve(sockets=[self.sock])),
            daemon=True)
        self.thread.start()
        wait_until(lambda: self.server.started, timeout=20, what="the GUI server started")

        async def add_hooks() -> None:
            for h in self.app.state.gui.fleet.handles.values():
                await h.axis.add_trace(hook)

        asyncio.run_coroutine_threadsafe(add_hooks(), self.loop).result(10)

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)
        self.sock.close()


@pytest.fixture(scope="module")
def gui() -> Iterator[Gui]:
    g = Gui()
    try:
        yield g
    finally:
        g.close()


@pytest.fixture(scope="module")
def browser() -> Iterator[WebDriver]:
    with browser_rig.chrome() as driver:
        yield driver


@pytest.fixture
def page(gui: Gui, browser: WebDriver) -> WebDriver:
    browser.get(gui.url)
    wait_until(lambda: browser.execute_script("return document.body.dataset.ready"),
               timeout=10, what="page ready")
    wait_until(lambda: browser.execute_script("return window.servobus.link.open"),
               what="WebSocket open")
    return browser


def js(driver: WebDriver, script: str, *args: object) -> Any:
    return driver.execute_script(script, *args)


def type_into(field: WebElement, text: str) -> None:
    field.clear()
    if text:
        field.send_keys(text)


def error_of(driver: WebDriver, field: WebElement) -> str:
    text: str = js(driver, "const n = arguments[0].nextElementSibling;"
                           "return n && n.classList.contains('field-error') ? n.textContent : ''",
                   field)
    return text


#: Clear the field's error, click the button (``arguments[1]``, none for a held jog), then
#: the field's error, whether it is marked invalid, and the panel's message, in one call: a
#: click runs the page's check before it returns.
PRESS = """const f = arguments[0], old = f.nextElementSibling;
    if (old && old.classList.contains('field-error')) old.textContent = '';
    if (arguments[1]) arguments[1].click();
    const n = f.nextElementSibling;  // made by the first error
    return [n && n.classList.contains('field-error') ? n.textContent : '',
            f.getAttribute('aria-invalid'),
            document.querySelector('.panel:not(.hidden) .msg').textContent];"""
SHOWN = """const f = arguments[0], n = f.nextElementSibling;
    return [n && n.classList.contains('field-error') ? n.textContent : '',
            f.getAttribute('aria-invalid'),
            document.querySelector('.panel:not(.hidden) .msg').textContent];"""


def press(driver: WebDriver, field: WebElement, button: WebElement) -> list[str]:
    """Press ``button`` (a jog: held a moment, released, as a person does); what shows."""
    if button.get_attribute("id") in HELD:
        js(driver, PRESS, field, None)
        ActionChains(driver).click_and_hold(button).pause(0.05).release().perform()
        shown: list[str] = js(driver, SHOWN, field)
        return shown
    shown = js(driver, PRESS, field, button)
    return shown


def check_field(driver: WebDriver, field: WebElement, buttons: list[str], what: str) -> None:
    """Each typed text, each button: the field says why, with the text it refused (so a
    stale error of the previous text does not count), and the panel says nothing was sent."""
    good = field.get_attribute("value") or ""
    pressed = [driver.find_element(By.ID, b) for b in buttons]
    for text in TYPED:
        type_into(field, text)
        says = text or "enter a number"
        for button in pressed:
            error, invalid, msg = press(driver, field, button)
            assert says in error and invalid == "true", (what, text, error)
            assert "not sent" in msg, (what, text, msg)
    type_into(field, good)  # the next field is judged alone


def test_every_motion_and_tuning_field_refuses_typed_junk_and_sends_nothing(
        page: WebDriver, gui: Gui) -> None:
    before = len(gui.sent)
    for field_id, buttons in MOTION.items():
        check_field(page, page.find_element(By.ID, field_id), buttons, f"#{field_id}")
    page.find_element(By.CSS_SELECTOR, '#tabs button[data-tab="tuning"]').click()
    gains = wait_until(lambda: page.find_elements(By.CSS_SELECTOR, "#gains-table input"),
                       what="the gains table")
    for field_id, buttons in TUNING.items():
        check_field(page, page.find_element(By.ID, field_id), buttons, f"#{field_id}")
    for field in gains:
        check_field(page, field, ["gains-apply"],
                    f"gain {field.get_attribute('data-gain')}")
    assert gui.sent[before:] == []  # nothing but reads reached any drive
    # the errors say why
    field = page.find_element(By.ID, "step-value")
    step = page.find_element(By.ID, "step-plus")
    for text, says in [("", "enter a number"), ("12,5", "decimal point"),
                       ("1e999", "too large"), ("fast", "not a number")]:
        type_into(field, text)
        assert says in press(page, field, step)[0], text


def test_a_good_value_clears_the_error_and_is_sent(page: WebDriver, gui: Gui) -> None:
    """The check of the test itself: the hook does see a move, and 0.25 is 0.25."""
    field = page.find_element(By.ID, "move-value")
    button = page.find_element(By.ID, "move-rel")
    type_into(field, "abc")
    assert press(page, field, button)[0]
    before = len(gui.sent)
    type_into(field, "0.25")
    assert press(page, field, button)[:2] == ["", None]
    wait_until(lambda: gui.sent[before:], what="the move on the wire")
    assert [t for t in gui.sent[before:] if "GO_RELATIVE_POS" in t], gui.sent[before:]
