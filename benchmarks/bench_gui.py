"""GUI scope pipeline: a virtual drive's 4 kHz trace x 8 channels to a headless Chromium page.

The GUI server runs in this process (uvicorn on a thread, three virtual drives); the page is
a real headless Chromium driven by Selenium, showing a 10 s rolling window of axis 1's eight
signals (position, position error, speed, current, four status bits) while the axis runs a
drive-generated 2 Hz sine. Figures:

* frames drawn per second by the page over 10 s (uPlot's draw hook; target >= 30);
* server CPU over the same 10 s, % of one core: this process's CPU minus this thread's
  (Selenium); it includes the virtual drives' physics and their 4 kHz recording
  (target <= 15 %);
* delay from a position change in the drive to its sample on the page: for 10 small moves,
  from the first trace sample that shows the move (drive time) to the ack of the first frame
  holding that sample, which the page sends after drawing it (target <= 100 ms; the worst
  of the 10 is marked, the ack's way back included).

Needs Chromium and chromedriver (Debian: apt-get install chromium chromium-driver).
"""

from __future__ import annotations

import asyncio
import functools
import json
import shutil
import statistics
import tempfile
import threading
import time
import urllib.request
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import uvicorn

from benchmarks.verdict import mark, percent
from servobus.gui.app import create_app
from servobus.gui.server import bind
from servobus.gui.state import GuiState

T = TypeVar("T")
WINDOW_S = 10.0
MEASURE_S = 10.0
MOVES = 10
CHANNELS = ["position", "position_error", "speed", "current", "enabled", "moving",
            "in_position", "alarm"]
CHROME_ARGS = ("--headless=new", "--no-sandbox", "--disable-gpu",
               "--disable-background-networking", "--disable-component-update",
               "--disable-sync", "--no-first-run", "--window-size=1600,1000")


class Server:
    """The GUI app on its own event loop thread, like ``servobus gui`` runs it."""

    def __init__(self) -> None:
        self.app = create_app()
        self.sock = bind("127.0.0.1", 0)
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}/"
        self.server = uvicorn.Server(uvicorn.Config(self.app, log_level="warning",
                                                    ws_per_message_deflate=False))
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        self.loop.run_until_complete(self.server.serve(sockets=[self.sock]))

    def __enter__(self) -> Server:
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline:
                raise RuntimeError("the GUI server did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)
        self.sock.close()

    @property
    def gui(self) -> GuiState:
        state: GuiState = self.app.state.gui
        return state

    def call(self, fn: Callable[[], Coroutine[Any, Any, T]]) -> T:
        """Run ``fn()`` on the server's loop (its data is only touched there)."""
        return asyncio.run_coroutine_threadsafe(fn(), self.loop).result(timeout=10)

    def post(self, path: str, body: object) -> Any:
        request = urllib.request.Request(self.url.rstrip("/") + path,
                                         data=json.dumps(body).encode(),
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=5) as r:
            return json.loads(r.read())


def browser() -> Any:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not chromium or not driver:
        raise RuntimeError("needs chromium and chromedriver (apt-get install chromium "
                           "chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in (*CHROME_ARGS, f"--user-data-dir={tempfile.mkdtemp(prefix='servobus-bench-')}"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(driver), options=options)


def wait(predicate: Callable[[], Any], timeout: float, what: str) -> Any:
    deadline = time.monotonic() + timeout
    while not (value := predicate()):
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(0.05)
    return value


def open_scope(page: Any, url: str) -> None:
    page.get(url)
    wait(lambda: page.execute_script("return document.body.dataset.ready === '1' && "
                                     "window.servobus.link.open"), 15, "the page")
    page.execute_script(f"""
        window.servobus.showTab("scope");
        const s = window.servobus.scope;
        document.querySelector("#scope-window").value = "{WINDOW_S:g}";
        document.querySelector("#trig-mode").value = "roll";
        s.channels = {json.dumps([{"axis": 1, "signal": c} for c in CHANNELS])};
        s.renderChannels(); s.build(); s.configure();""")


def position_delays(srv: Server) -> list[float]:
    """Drive-side time of each move's first changed sample -> ack of the frame holding it."""
    delays = []
    for k in range(MOVES):
        before = srv.call(_last_time)
        srv.post("/api/axes/1/move", {"value": 2000 if k % 2 == 0 else -2000,
                                      "unit": "counts", "relative": True})
        time.sleep(0.5)
        delays.append(srv.call(functools.partial(_delay_after, srv.gui, before)))
    return delays


async def _last_time() -> float:
    return time.monotonic()


async def _delay_after(gui: GuiState, t_before: float) -> float:
    ring = gui.samplers[1].ring
    i = ring.index_at(t_before)
    base = ring.value("position", i)
    while ring.value("position", i) == base:
        i += 1
    t_change = ring.time(i)
    session = next(iter(gui.sessions))
    return next(ack - t_change for _, newest, ack in session.drawn if newest >= t_change)


def main() -> None:
    print(f"GUI scope pipeline: virtual drive trace 4000 Hz x {len(CHANNELS)} channels, "
          f"{WINDOW_S:g} s window, headless Chromium")
    with Server() as srv:
        page = browser()
        try:
            open_scope(page, srv.url)
            srv.post("/api/axes/1/wave", {"kind": "sine", "amplitude": 2000, "hz": 2})
            wait(lambda: page.execute_script("return window.servobus.scope.stats.frames") > 20,
                 10, "scope frames")
            time.sleep(2.0)
            drawn0 = page.execute_script("return window.servobus.scope.stats.drawn")
            cpu0, own0, t0 = time.process_time(), time.thread_time(), time.monotonic()
            time.sleep(MEASURE_S)
            cpu1, own1, t1 = time.process_time(), time.thread_time(), time.monotonic()
            drawn1 = page.execute_script("return window.servobus.scope.stats.drawn")
            state = page.execute_script("return window.servobus.scope.stats.state")
            frame_points = page.execute_script("return window.servobus.scope.frame.n")
            draw_ms = page.execute_script("return window.servobus.scope.stats.drawMs")
            fps = (drawn1 - drawn0) / (t1 - t0)
            cpu = ((cpu1 - cpu0) - (own1 - own0)) / (t1 - t0)
            srv.post("/api/axes/1/wave", {"kind": "off"})
            srv.post("/api/stop_all", {})
            time.sleep(1.0)
            delays = position_delays(srv)
        finally:
            page.quit()
    lat = state["latency_ms"]
    print(f"  frames drawn: {fps:5.1f} /s over {MEASURE_S:g} s "
          f"{mark('gui: scope frames drawn per s', fps, at_least=30, show='{:g}/s'.format)}"
          f"  ({frame_points} points x {len(CHANNELS)} channels per frame, "
          f"{int(WINDOW_S * 4000):,} samples per channel in the window; last draw "
          f"{draw_ms:.1f} ms)")
    print(f"  server CPU: {cpu * 100:5.1f} % of one core "
          f"{mark('gui: server CPU share', cpu, at_most=0.15, show=percent)}"
          "  (incl. 3 virtual drives and the 4 kHz recording)")
    worst = max(delays)
    print(f"  position change in the drive -> drawn on the page: median "
          f"{statistics.median(delays) * 1000:.0f} ms, worst {worst * 1000:.0f} ms of {MOVES} "
          f"{mark('gui: drive-to-page delay', worst * 1000, at_most=100, show='{:g} ms'.format)}")
    print("  delays, ms: " + " ".join(f"{d * 1000:.0f}" for d in delays))
    print(f"  every frame's newest sample -> page ack: median {lat['median']:.0f} ms, "
          f"p95 {lat['p95']:.0f} ms")


if __name__ == "__main__":
    from benchmarks.verdict import summary

    main()
    print(summary())
