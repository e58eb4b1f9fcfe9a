"""The page shows what it knows and nothing more (issue 29), in a real headless Chromium:
without its server it says so in a banner and disables every control that sends something,
and comes back by itself when a server is back on the same port; an offline axis's card is
greyed with "last seen N s ago" and its controls are disabled; back with a possible power
loss, it offers Acknowledge and motion waits for it. ``servobus gui --machine`` over an
in-process virtual drive and one in its own process (killed here). Skips in one line
without Chromium, chromedriver or Selenium."""

from __future__ import annotations

import json
import subprocess
import sys
import urllib.request
from pathlib import Path
from typing import Any

import browser_rig
import pytest
from drive_process_rig import procs as procs  # the fixture, for this module
from drive_process_rig import sim_url, start_sim
from rig import free_port, wait_until
from subprocess_rig import read_line, stop_process

browser_rig.skip_without_browser()
pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]

#: Every control that moves an axis (the selected one, or all for STOP ALL).
MOTION = ("#stop-all", "#jog-plus", "#jog-minus", "#move-abs", "#move-rel", "#turn-run",
          "[data-action=enable]", "[data-action=stop]", "#scope-jog-plus", "#step-plus")


def start_gui(machine: Path, port: int) -> tuple[subprocess.Popen[str], str]:
    """``servobus gui`` once it says its URL (a loaded CI host took over 20 s to start one
    beside two CPU-bound processes); stopped here if it never does."""
    proc = subprocess.Popen([sys.executable, "-m", "servobus", "gui", "--machine",
                             str(machine), "--port", str(port), "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        return proc, read_line(proc, "servobus gui: http://", timeout=60).split()[-1]
    except BaseException:
        stop_process(proc)
        raise


def disabled(page: Any, selector: str) -> bool:
    return bool(page.execute_script(
        "return document.querySelector(arguments[0]).matches(':disabled')", selector))


def card(page: Any, name: str) -> dict[str, Any]:
    """The card of axis ``name``: its classes and the text it shows."""
    doc: dict[str, Any] = page.execute_script("""
        const c = [...document.querySelectorAll('.axis-card')]
            .find((n) => n.querySelector('.name').textContent === arguments[0]);
        return {classes: [...c.classList], seen: c.querySelector('[data-v=seen]').textContent};
    """, name)
    return doc


def recovery(page: Any, name: str) -> str:
    """The power-loss / interrupted line of axis ``name``'s card ("" when hidden)."""
    return str(page.execute_script("""
        const c = [...document.querySelectorAll('.axis-card')]
            .find((n) => n.querySelector('.name').textContent === arguments[0]);
        const box = c.querySelector('[data-v=recovery-box]');
        return box.classList.contains('hidden') ? '' : box.textContent;
    """, name))


def far_status(base: str) -> dict[str, Any]:
    """Axis 2's (far's) status as the server has it."""
    with urllib.request.urlopen(base + "api/axes", timeout=10) as r:
        doc: dict[str, Any] = json.loads(r.read())[1]["status"]
    return doc


def post(base: str, path: str, body: object) -> None:
    request = urllib.request.Request(base + path, data=json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=10) as r:
        assert r.status == 200


def test_the_page_without_its_server_and_with_an_offline_axis(
        tmp_path: Path, procs: list[subprocess.Popen[str]]) -> None:
    drive_port, gui_port = free_port(), free_port()
    procs.append(start_sim("dyn232", drive_port))
    machine = tmp_path / "m.toml"
    machine.write_text('[axes.near]\nurl = "sim://dyn232?fast=1"\nid = 1\nunit = "rev"\n\n'
                       f'[axes.far]\nurl = "{sim_url("dyn232", drive_port)}"\nid = 1\n'
                       'unit = "rev"\n', encoding="utf-8")
    first, base = start_gui(machine, gui_port)
    procs.append(first)
    with browser_rig.chrome() as page:
        page.get(base)
        wait_until(lambda: page.execute_script(
            "return document.body.dataset.ready === '1' && window.servobus.link.open"
            " && document.querySelectorAll('.axis-card.stale').length === 0"),
            timeout=20, what="the page live, every card fresh")
        assert not any(disabled(page, s) for s in MOTION)
        page.execute_script("window.sameDocument = true")

        stop_process(first)  # the server is gone: the page says so, nothing can be pressed
        wait_until(lambda: page.execute_script(
            "return !document.querySelector('#server-banner').classList.contains('hidden')"),
            timeout=20, what="the banner")
        assert all(disabled(page, s) for s in MOTION), [s for s in MOTION
                                                        if not disabled(page, s)]
        page.execute_script("document.querySelector('#move-abs').click()")
        assert "fetch" not in page.find_element("css selector", "#motion-msg").text
        wait_until(lambda: "no server · last seen" in card(page, "near")["seen"],
                   what="the values greyed with their age")

        second, _ = start_gui(machine, gui_port)  # a server back on the same port
        procs.append(second)
        wait_until(lambda: page.execute_script(
            "return document.querySelector('#server-banner').classList.contains('hidden')"),
            timeout=30, what="the page back by itself")
        wait_until(lambda: not disabled(page, "#move-abs"), what="motion controls back")
        assert page.execute_script("return window.sameDocument") is True  # not reloaded

        post(base, "api/axes/2/move", {"value": 50, "unit": "rev"})  # running when ...
        # (seen running first: the drive took the move. A restart right after the move is
        # flagged too - tests/machine/test_machine_motion_seen.py, the cause of the red CI
        # run of 2026-11-27 - but a move the drive refused leaves it standing at 0, where a
        # restart cannot be told: docs/machine.md, "Power loss")
        wait_until(lambda: far_status(base)["moving"], timeout=20, what="far running")
        procs[0].kill()  # ... the far axis's drive dies: its card greys, with its age
        wait_until(lambda: "offline" in card(page, "far")["classes"]
                   and "offline · last seen" in card(page, "far")["seen"],
                   timeout=30, what="far greyed, last seen")
        assert "stale" in card(page, "far")["classes"] and not card(page, "near")["seen"]
        page.execute_script("document.querySelector('.axis-card[data-axis=\"2\"]').click()")
        wait_until(lambda: disabled(page, "#move-abs") and disabled(page, "#jog-plus"),
                   what="far's controls disabled")
        assert "far is offline" in page.find_element("css selector", "#motion-gate").text
        assert not disabled(page, "#stop-all")  # STOP ALL still stops the others

        procs.append(start_sim("dyn232", drive_port))  # back, flagged: motion waits for a person
        wait_until(lambda: "may have lost power" in recovery(page, "far"), timeout=60,
                   what="far online again, its power loss shown")
        wait_until(lambda: not card(page, "far")["seen"], what="far's values fresh again")
        assert disabled(page, "#move-abs") and not disabled(page, "[data-action=enable]")
        assert "lost power" in page.find_element("css selector", "#motion-gate").text
        page.execute_script("document.querySelector('.axis-card[data-axis=\"2\"] button.ack')"
                            ".click()")
        wait_until(lambda: not recovery(page, "far") and not disabled(page, "#move-abs"),
                   what="acknowledged: motion allowed again")
