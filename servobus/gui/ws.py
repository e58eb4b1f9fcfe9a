"""The page's WebSocket: live status out, jog and scope control in, scope frames out.

Messages from the page (JSON): ``jog`` {axis, speed} (``speed`` in the axis's speed
unit, servobus.gui.fleet.Units; ``rpm`` instead is still taken; repeated while the button is held),
``jog_stop`` {axis}, ``turn`` {axis, speed} (renews the constant speed the page started with
``POST /api/axes/N/turn`` {speed, page}, repeated while it is on), ``turn_stop`` {axis},
``tune_renew`` {axis} (keeps the page's auto-tune run alive, servobus.gui.autotune;
repeated every 150 ms while it runs), ``stop_all``, ``scope`` {settings}, ``scope_run`` {running},
``scope_arm``, ``scope_csv``, ``ack`` {seq}, ``io_watch`` {axis or null}. To the page:
``hello``, ``status`` (every :data:`STATUS_PERIOD_S`; each axis as StatusMonitor.view
gives it: its last values with their age and the machine's live link state, issue 29),
``io`` (the watched axis's virtual outputs and state, as often), ``scope_state``, ``csv``,
``error`` (``message``; ``request``: the type of the message it answers, ``received``: that
message's start), ``stopped`` (JSON) and scope frames (binary, servobus.gui.frames).
Message sizes and JSON nesting are bounded (servobus.gui.limits).

The page owns its jogs and constant speeds as ``page N`` (N: ``hello``'s ``owner``;
servobus.gui.jog). ``status`` carries ``jog`` (axis -> rpm of every running lease),
``leases`` (axis -> owner, rpm, at_limit, mine) and ``ended`` (axis -> why this page's
motion ended without it letting go), ``tune`` (axis -> its auto-tune run: progress, then
the table). When the WebSocket closes, for whatever reason, every motion of this page
stops first, and its auto-tune runs abort.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import math
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from servobus import bounded_json
from servobus.errors import ServobusError
from servobus.gui import fair, limits
from servobus.gui.api_io import snapshot
from servobus.gui.jog import page_owner
from servobus.gui.scope_session import ScopeSession, ScopeSettings
from servobus.gui.state import GuiState

log = logging.getLogger(__name__)
STATUS_PERIOD_S = 0.1
_owners = itertools.count(1)


class PageLink:
    """One connected page."""

    def __init__(self, ws: WebSocket, gui: GuiState) -> None:
        self.ws, self.gui = ws, gui
        self.owner = next(_owners)
        self._lock = asyncio.Lock()
        self.session = ScopeSession(gui.samplers, self.send_bytes, self.send_json)
        self.io_axis: int | None = None  # the axis whose virtual I/O the page watches

    async def send_json(self, doc: dict[str, object]) -> None:
        async with self._lock:
            await self.ws.send_text(json.dumps(doc, allow_nan=False, default=_plain))

    async def send_bytes(self, data: bytes) -> None:
        async with self._lock:
            await self.ws.send_bytes(data)

    async def push_status(self) -> None:
        while True:
            gui = self.gui
            active = gui.jog.active()
            mine = page_owner(self.owner)
            now = time.time()
            await self.send_json({
                "type": "status",
                "axes": [_finite(gui.monitor.view(i, now)) for i in gui.monitor.snapshots],
                "jog": {str(k): v["rpm"] for k, v in active.items()},
                "leases": {str(k): {**v, "mine": v["owner"] == mine}
                           for k, v in active.items()},
                "ended": {str(k): v for k, v in gui.jog.ended(self.owner).items()},
                "alarms": len(gui.monitor.log),
                "tune": gui.autotune.views(self.owner),
            })
            await asyncio.sleep(STATUS_PERIOD_S)

    async def push_io(self) -> None:
        while True:
            axis = self.io_axis
            if axis is not None:
                try:
                    doc = await snapshot(self.gui.fleet.get(axis))
                except ServobusError as exc:  # not a virtual drive, or no such axis
                    self.io_axis = None
                    await self.send_json({"type": "error", "message": str(exc),
                                          "request": "io_watch"})
                else:
                    await self.send_json({"type": "io", **doc})
            await asyncio.sleep(STATUS_PERIOD_S)

    async def handle(self, doc: dict[str, object]) -> None:
        kind = doc.get("type")
        gui, session = self.gui, self.session
        if kind == "ack":
            seq = doc.get("seq")
            if isinstance(seq, int):
                session.ack(seq)
        elif kind == "jog":
            axis = _int(doc, "axis")
            await gui.jog.jog(self.owner, axis, _speed(gui, doc, axis))
        elif kind == "turn":
            axis = _int(doc, "axis")
            await gui.jog.turn(axis, _speed(gui, doc, axis), page=self.owner, start=False)
        elif kind == "tune_renew":
            gui.autotune.renew(self.owner, _int(doc, "axis"))
        elif kind in ("jog_stop", "turn_stop"):
            await gui.jog.release(self.owner, _int(doc, "axis"))
        elif kind == "stop_all":
            failed = {str(k): v for k, v in (await gui.stop_all()).items() if v}
            await self.send_json({"type": "stopped", "failed": failed})
        elif kind == "scope":
            settings = doc.get("settings")
            if not isinstance(settings, dict):
                raise ValueError("scope: settings must be an object")
            session.configure(ScopeSettings.parse(settings, gui.fleet.handles.keys()))
            session.set_running(True)
        elif kind == "scope_run":
            session.set_running(bool(doc.get("running", True)))
        elif kind == "scope_arm":
            session.rearm()
        elif kind == "io_watch":
            self.io_axis = None if doc.get("axis") is None else _int(doc, "axis")
        elif kind == "scope_csv":
            await self.send_json({"type": "csv", "text": session.csv()})
        else:
            raise ValueError(f"unknown message type {kind!r}")

    async def receive(self, message: Mapping[str, Any]) -> bool:
        """Answer one message from the page; False when the socket was closed for it.

        Every bad message gets an ``error`` naming that message (its type, and its start
        in ``received``) and the session goes on; only one over the size limit closes the
        socket (1009, servobus.gui.limits). A message whose handling fails unexpectedly (a
        bug) is answered with an ``error`` too, and logged in one line (servobus.gui.boundary).
        """
        text = message.get("text")
        data = message.get("bytes")
        size = len(data) if isinstance(data, bytes) else len(str(text or "").encode())
        if size > limits.MAX_MESSAGE_BYTES:
            await self.ws.close(limits.CLOSE_TOO_BIG,
                                f"message of {size} bytes: at most {limits.MAX_MESSAGE_BYTES}")
            return False
        if not isinstance(text, str):
            await self.refuse("a binary message: the page sends JSON text", "", "(binary)")
            return True
        kind = ""
        try:
            doc = bounded_json.loads(text, max_bytes=limits.MAX_MESSAGE_BYTES)
            if not isinstance(doc, dict):
                raise ValueError("a message is a JSON object")
            kind = str(doc.get("type", ""))
            await self.handle(doc)
        except (ValueError, ServobusError) as exc:
            await self.refuse(str(exc), kind, bounded_json.excerpt(text))
        except WebSocketDisconnect:
            raise
        except Exception as exc:  # this message's boundary: a bug fails it, not the page
            if self.ws.application_state != WebSocketState.CONNECTED:
                raise  # the socket is gone: the page ends
            log.error("GUI WebSocket message %r of page %d failed: %s: %s", kind[:40],
                      self.owner, type(exc).__name__, bounded_json.excerpt(str(exc), 300))
            log.debug("GUI WebSocket message failed", exc_info=True)
            await self.refuse(f"internal error ({type(exc).__name__}); the page and the "
                              "server go on", kind, bounded_json.excerpt(text))
        return True

    async def turn_away(self) -> None:
        """One page more than :data:`servobus.gui.fair.MAX_PAGES`: told why, then closed
        with 1013 ("try again later"); the page's own reconnection tries again."""
        text = f"the GUI serves at most {fair.MAX_PAGES} pages at once: close one"
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
            await self.ws.accept()
            await self.send_json({"type": "error", "message": text, "request": ""})
            await self.ws.close(fair.CLOSE_TRY_AGAIN_LATER, text)

    async def refuse(self, text: str, kind: str, received: str) -> None:
        await self.send_json({"type": "error", "message": text, "request": kind,
                              "received": received})

    async def serve(self) -> None:
        gui = self.gui
        if len(gui.sessions) >= fair.MAX_PAGES:
            await self.turn_away()
            return
        gui.sessions.add(self.session)  # before any await: pages opening at once count too
        tasks: list[asyncio.Task[None]] = []
        try:
            await self.ws.accept()
            gui.jog.pages.add(self.owner)
            tasks = [asyncio.create_task(_quietly(self.push_status)),
                     asyncio.create_task(_quietly(self.session.run)),
                     asyncio.create_task(_quietly(self.push_io))]
            await self.send_json({"type": "hello", "owner": self.owner, "url": gui.fleet.url,
                                  "axes": [h.identity() for h in gui.fleet.handles.values()]})
            while True:
                message = await self.ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                if not await self.receive(message):
                    break
                # a page that floods: its queued messages wait for the others' turn
                await asyncio.sleep(0)
        except (WebSocketDisconnect, RuntimeError):
            pass  # the page went away (closed, reloaded, network dropped)
        finally:
            gui.jog.pages.discard(self.owner)  # no Run names it any more
            await gui.jog.release(self.owner)  # first: a jog never outlives its page
            await gui.autotune.release(self.owner)  # nor an auto-tune run
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            self.session.close()
            gui.sessions.discard(self.session)


async def _quietly(fn: Callable[[], Awaitable[None]]) -> None:
    """Run a sender until the socket fails (then the receive loop ends the page)."""
    try:
        await fn()
    except (WebSocketDisconnect, RuntimeError, ConnectionError):
        pass
    except Exception:  # a bug in a sender must not leave the page silently stale
        log.exception("GUI WebSocket sender failed")


def _int(doc: dict[str, object], key: str) -> int:
    value = doc.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{key} must be an integer, got {value!r}")
    return value


def _speed(gui: GuiState, doc: dict[str, object], axis: int) -> float:
    """A jog's or constant speed's ``speed`` in the axis's shown speed unit (issue 33), or
    ``rpm`` (an integer, as before) converted to it."""
    if "speed" in doc:
        value = doc["speed"]
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or not math.isfinite(value):
            raise ValueError(f"speed must be a finite number, got {value!r}")
        return float(value)
    return _int(doc, "rpm") * gui.fleet.get(axis).units().per_rpm


def _finite(snap: dict[str, object]) -> dict[str, object]:
    """JSON has no NaN or infinity: such a reading is sent as null."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in snap.items()}


def _plain(value: object) -> object:
    return str(value)


async def endpoint(ws: WebSocket) -> None:
    await PageLink(ws, ws.app.state.gui).serve()
