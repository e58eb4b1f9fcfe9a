"""The page in the axis's own units and names, at any width (issue 33), in a real headless
Chromium (Selenium + Debian's chromium-driver).

One page load of a machine file (tests/machine/machine_rig.MIXED: axis x in mm on a virtual
DYN232M drive, limits -10..300, speed 50 mm/s): the Motion, Scope and Tuning panels show
mm and mm/s first, a jog held into the soft limit releases its button and says so, and the
page at 1600x1000, 800x900 and 390x844 (the viewport set through the DevTools protocol)
never scrolls sideways, with STOP ALL and the jog buttons on screen on the phone. Without
Chromium, chromedriver or Selenium the module is skipped with one line saying which is
missing.
"""

from __future__ import annotations

import asyncio
import math
import re
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import browser_rig
import pytest
import rig
from machine.machine_rig import write_machine

browser_rig.skip_without_browser()

from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]
#: Every wait's deadline: generous, for a machine shared with other jobs (a wait ends as
#: soon as its condition holds).
WAIT = 60.0


def wait_until(predicate: Callable[[], Any], *, what: str, timeout: float = WAIT) -> Any:
    return rig.wait_until(predicate, timeout=timeout, what=what)


class Gui:
    """``servobus gui --machine FILE`` in this process (uvicorn on a thread)."""

    def __init__(self, machine: Path) -> None:
        import uvicorn

        from servobus.gui.app import create_app
        from servobus.gui.server import bind, uvicorn_config

        self.app = create_app(machine=machine)
        self.sock = bind("127.0.0.1", 0)
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}/"
        self.server = uvicorn.Server(uvicorn_config(self.app))
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(
            target=lambda: self.loop.run_until_complete(self.server.serve(sockets=[self.sock])),
            daemon=True)
        self.thread.start()
        wait_until(lambda: self.server.started, timeout=WAIT, what="the GUI server started")

    def note_alarm(self) -> None:
        """An alarm-log entry of axis x, written on the server's loop (as the monitor does)."""
        async def note() -> None:
            self.app.state.gui.monitor.note(1, "alarm", "over-current (a test entry)", 5)

        asyncio.run_coroutine_threadsafe(note(), self.loop).result(10)

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)
        self.sock.close()


@pytest.fixture(scope="module")
def gui(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Gui]:
    server = Gui(write_machine(tmp_path_factory.mktemp("browser-units")))
    try:
        yield server
    finally:
        server.close()


@pytest.fixture(scope="module")
def page(gui: Gui) -> Iterator[WebDriver]:
    with browser_rig.chrome() as driver:
        viewport(driver, 1600, 1000)
        driver.get(gui.url)
        wait_until(lambda: driver.execute_script("return document.body.dataset.ready"),
                   timeout=WAIT, what="page ready")
        wait_until(lambda: driver.execute_script("return window.servobus.link.open"),
                   timeout=WAIT, what="WebSocket open")
        yield driver


def viewport(driver: WebDriver, width: int, height: int) -> None:
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
        "width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})


def js(driver: WebDriver, script: str, *args: object) -> Any:
    return driver.execute_script(script, *args)


def text(driver: WebDriver, selector: str) -> str:
    return str(js(driver, "return document.querySelector(arguments[0]).textContent", selector))


def tab(driver: WebDriver, name: str) -> None:
    driver.find_element(By.CSS_SELECTOR, f'#tabs button[data-tab="{name}"]').click()


#: What a Python repr looks like in a line: ``Name(``, ``<Enum.X: 0>``, ``b'...'``.
REPR = re.compile(r"[A-Za-z_]\(|<\w+\.\w+: |\bb'")


def card(driver: WebDriver, name: str) -> None:
    """Select the axis ``name`` by its card."""
    driver.find_element(By.XPATH, f'//div[@class="axis-card" or contains(@class, "axis-card ")]'
                                  f'[.//span[@class="name" and text()="{name}"]]').click()


def options(driver: WebDriver, selector: str) -> list[str]:
    return list(js(driver, "return [...document.querySelector(arguments[0]).options]"
                           ".map((o) => o.textContent)", selector))


#: Sideways overflow of the page, and the rectangles of the elements named (in the viewport).
LAYOUT = """const d = document.documentElement;
    return [d.scrollWidth - window.innerWidth, window.innerWidth, window.innerHeight,
      arguments[0].map((s) => { const r = document.querySelector(s).getBoundingClientRect();
        return [s, r.left, r.top, r.right, r.bottom]; })];"""


def test_a_mm_axis_speaks_mm_and_fits_every_width(page: WebDriver, gui: Gui) -> None:
    # Motion: x's own units first, the jog from the file's speed (50 mm/s)
    assert (text(page, "#jog-unit"), text(page, "#turn-unit")) == ("mm/s", "mm/s")
    assert js(page, "return document.querySelector('#jog-rpm').value") == "50"
    assert text(page, "#wave-unit") == "mm" and options(page, "#move-unit")[0] == "mm"
    wait_until(lambda: " mm" in text(page, "#motion-readout"), what="the readout in mm")
    assert "counts" in text(page, "#motion-readout")  # the secondary readout
    # a jog held into the soft limit at -10 mm: the button goes dark and the page says so
    jog = page.find_element(By.ID, "jog-minus")
    hold = ActionChains(page).click_and_hold(jog)
    hold.perform()
    try:
        wait_until(lambda: "stopped at soft limit" in text(page, "#motion-msg"), timeout=WAIT,
                   what="the page says the jog stopped at the soft limit")
        assert "x" in text(page, "#motion-msg")
        assert "held" not in (jog.get_attribute("class") or "")
    finally:
        ActionChains(page).release(jog).perform()
    # Scope: channels, legend and trigger level in mm and mm/s, named x
    tab(page, "scope")
    wait_until(lambda: "x position [mm]" in text(page, ".u-legend"), what="the legend in mm")
    legend = text(page, ".u-legend")
    assert "x speed [mm/s]" in legend and "rpm" not in legend and "counts" not in legend
    assert "position [mm]" in options(page, "#scope-channels select[data-field=signal]")
    assert text(page, "#trig-unit") == "mm"
    # channels follow the selected axis unless pinned (choosing a channel's axis pins it)
    channel_axes = "return [...document.querySelectorAll('#scope-channels " \
                   "select[data-field=axis]')].map((s) => s.value)"
    card(page, "c")
    wait_until(lambda: js(page, channel_axes) == ["3", "3"], what="channels follow c")
    wait_until(lambda: "c position [deg]" in text(page, ".u-legend"), what="c in deg")
    js(page, """const s = document.querySelector('#scope-channels select[data-field=axis]');
                s.value = '1'; s.dispatchEvent(new Event('change'));""")
    card(page, "y")
    wait_until(lambda: js(page, channel_axes) == ["1", "2"], what="x pinned, y followed")
    # a capture survives the tabs: armed here, caught while Motion shows, kept on return
    js(page, """document.querySelector('#trig-mode').value = 'normal';
                document.querySelector('#trig-level').value = '-5';
                window.servobus.scope.configure();""")
    wait_until(lambda: js(page, "return window.servobus.scope.stats.state?.waiting"),
               what="the trigger armed")
    tab(page, "motion")
    card(page, "x")  # channel 1 is pinned to x; channel 2 follows
    # the move goes over HTTP, the new channels over the WebSocket: a loaded server applied
    # the move first and the re-armed trigger missed its crossing; so, the server's scope
    # on x alone and armed before the move
    wait_until(lambda: js(page, channel_axes) == ["1", "1"], what="channel 2 follows x")
    wait_until(lambda: js(page, """const s = window.servobus.scope.stats.state;
                                   return Boolean(s && s.waiting && s.sources
                                       .map((x) => x.axis).join() === '1');"""),
               what="the server's scope on x alone, armed")
    js(page, """document.querySelector('#move-value').value = '10';
                document.querySelector('#move-unit').value = 'mm';
                document.querySelector('#move-rel').click();""")  # -10 mm up through -5 mm
    wait_until(lambda: js(page, "return window.servobus.scope.lastTriggered !== null"),
               timeout=WAIT, what="the move caught while the Motion tab shows")
    tab(page, "scope")
    caught = js(page, "const f = window.servobus.scope.frame; return [f.flags & 1, "
                      "Math.min(...f.ys[0].filter((v) => v === v)), "
                      "Math.max(...f.ys[0].filter((v) => v === v))]")
    assert caught[0] == 1 and caught[1] < -5 < caught[2], caught  # in mm, through -5
    # a move from the Scope tab itself, in x's unit
    assert text(page, "#scope-move-unit") == "mm"
    # from where x rests: the jog stopped at the soft limit where its lead ran out (near
    # -10 mm, not exactly), and the +10 mm above was relative to that
    def x_mm() -> float:
        return float(text(page, '.axis-card[data-axis="1"] [data-v=position]').split()[0])

    last = [math.nan]

    def at_rest() -> bool:  # the same reading on two polls half a second apart
        now = x_mm()
        same, last[0] = now == last[0], now
        return same

    rig.wait_until(at_rest, timeout=WAIT, poll=0.5, what="x at rest after its move")
    start = x_mm()
    page.find_element(By.ID, "scope-move-minus").click()
    wait_until(lambda: "move by -1 mm: sent to x" in text(page, "#scope-msg"),
               what="the move from the Scope tab")
    # auto (the default mode): the capture caught on another tab is held on return, paused
    wait_until(lambda: abs(x_mm() - (start - 1)) < 0.01, timeout=WAIT,
               what="x 1 mm below where it rested")
    # the level half-way up the next move, from where x is now (a fixed -0.5 mm was never
    # crossed when the jog had rested more than 0.5 mm short of -10 mm: one red run)
    js(page, f"""document.querySelector('#trig-mode').value = 'auto';
                document.querySelector('#trig-level').value = '{start - 0.5:.3f}';
                window.servobus.scope.configure();""")
    before = js(page, "return window.servobus.scope.lastTriggered?.seq ?? 0")
    tab(page, "motion")
    js(page, """document.querySelector('#move-value').value = '1';
                document.querySelector('#move-rel').click();""")  # 1 mm up through the level
    wait_until(lambda: js(page, "return window.servobus.scope.lastTriggered?.seq ?? 0") != before,
               timeout=WAIT, what="the move caught in auto mode while Motion shows")
    tab(page, "scope")
    held = js(page, "const s = window.servobus.scope; return [s.running, s.frame.flags & 1]")
    assert held == [False, 1]  # paused on the capture: a free-running frame does not replace it
    page.find_element(By.ID, "scope-run").click()  # Run goes on
    # Diagnostics: one decoded line per transaction, no Python repr, times that do not wrap
    tab(page, "diag")
    wait_until(lambda: "⇄" in text(page, "#traffic"), what="transactions in the log")
    assert not REPR.search(text(page, "#traffic"))
    # Tuning: the step in mm first
    tab(page, "tuning")
    assert options(page, "#step-unit")[0] == "mm"
    # lights: a shape besides the colour (lit and unlit differ in more than colour)
    shapes = js(page, "return [...document.querySelectorAll('.light')].map((n) => "
                      "[n.classList.contains('on'), getComputedStyle(n, '::before').content])")
    assert {on for on, _ in shapes} == {True, False}  # x is enabled, never in alarm
    assert len({shape for _, shape in shapes}) >= 2
    assert all(shape != "none" for _, shape in shapes)
    # 800 px: no sideways scroll, every tab visible
    tab(page, "motion")
    viewport(page, 800, 900)
    over, width, _, rects = js(page, LAYOUT, [f'#tabs button[data-tab="{t}"]' for t in
                                              ("motion", "params", "scope", "tuning", "diag")])
    assert over <= 0 and width == 800
    assert all(left >= 0 and right <= width for _, left, _, right, _ in rects), rects
    for name in ("scope", "tuning", "diag", "params", "motion"):  # every panel at 800 px
        tab(page, name)
        assert js(page, LAYOUT, [])[0] <= 0, name
    # 390 px: STOP ALL and both jog buttons inside the viewport, no sideways scroll
    viewport(page, 390, 844)
    over, width, height, rects = js(page, LAYOUT, ["#stop-all", "#jog-minus", "#jog-plus"])
    assert over <= 0 and width == 390
    for name, left, top, right, bottom in rects:
        assert left >= 0 and right <= width and top >= 0 and bottom <= height, name
    for name in ("scope", "tuning", "diag", "params"):  # every panel fits the phone
        tab(page, name)
        assert js(page, LAYOUT, [])[0] <= 0, name
    # the alarm log on the phone: named, its time on one line
    gui.note_alarm()
    tab(page, "diag")
    row = wait_until(lambda: js(page, "const r = document.querySelector('#alarm-log tr.alarm');"
                                      "if (!r) return null; const t = document.createRange();"
                                      "t.selectNodeContents(r.cells[0]);"
                                      "return [t.getClientRects().length, r.cells[1].textContent]"),
                     what="the alarm row")
    assert row == [1, "x"]  # the time's text is one line box
