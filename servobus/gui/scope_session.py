"""One page's scope: channels, time base, trigger, pause; frames at the page's pace.

Each tick (:data:`FRAME_INTERVAL_S`) the session looks for a completed trigger capture
(servobus.gui.trigger) or, rolling, reduces what is new (servobus.gui.decimate), and sends
one binary frame (servobus.gui.frames) when the page has drawn the previous one. The delay
from a frame's newest sample (drive-side time) to the page's ack is measured per frame.

Channels may come from several axes; each axis's samples keep their own times and are
reduced onto one bucket grid, so the page gets one x array.
"""

from __future__ import annotations

import asyncio
import dataclasses
import io
import math
import statistics
import time
from array import array
from collections import deque
from collections.abc import Awaitable, Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

from servobus.gui import frames
from servobus.gui.decimate import (
    Columns,
    RollingDecimator,
    assemble,
    bucket_count,
    decimate_window,
    use_pairs,
)
from servobus.gui.sampler import MAX_WINDOW_S, AxisSampler
from servobus.gui.signals import SIGNALS
from servobus.gui.trigger import MODES, Edge, TriggerSettings, TriggerTracker

FRAME_INTERVAL_S = 0.02  # at most 50 frames/s; fewer when the page draws slower
STATE_INTERVAL_S = 0.25
ACK_GIVE_UP_S = 1.0  # a frame unanswered this long no longer holds the next one back
#: Frames on their way or being drawn: two lets the server build the next frame while the
#: page draws one; a page that draws slowly still never gets a backlog.
MAX_IN_FLIGHT = 2
AUTO_GRACE_S = 0.25  # auto mode free-runs after window + this without a trigger
LATE_AXIS_S = 0.5  # a capture waits at most this long for a slower axis's samples
#: Channels of one page's scope (a cap per page, servobus.gui.fair): one session per page,
#: a new configuration replaces the last one and its sampler subscriptions.
MAX_CHANNELS = 8
MIN_WINDOW_S = 0.005
WIDTH_RANGE = (50, 4000)
CSV_MAX_ROWS = 400_000

SendBytes = Callable[[bytes], Awaitable[None]]
SendJson = Callable[[dict[str, object]], Awaitable[None]]


@dataclass(frozen=True)
class Channel:
    axis: int
    signal: str


@dataclass(frozen=True)
class ScopeSettings:
    channels: tuple[Channel, ...]
    trigger: TriggerSettings
    trigger_channel: int = 0
    width_px: int = 1000

    @property
    def window_s(self) -> float:
        return self.trigger.window_s

    @classmethod
    def parse(cls, doc: Mapping[str, object], axes: Collection[int]) -> ScopeSettings:
        """From the page's JSON; ValueError says what is wrong."""
        raw = doc.get("channels")
        if not isinstance(raw, list):
            raise ValueError(f"channels: a list of 1 to {MAX_CHANNELS} {{axis, signal}}")
        if not 1 <= len(raw) <= MAX_CHANNELS:
            raise ValueError(f"a page's scope shows 1 to {MAX_CHANNELS} channels, "
                             f"got {len(raw)}")
        channels = []
        for c in raw:
            if not isinstance(c, dict):
                raise ValueError(f"channel {c!r}: expected {{axis, signal}}")
            axis, signal = c.get("axis"), c.get("signal")
            if not isinstance(axis, int) or axis not in axes:
                raise ValueError(f"channel axis {axis!r}: axes are {sorted(axes)}")
            if signal not in SIGNALS:
                raise ValueError(f"signal {signal!r}: one of {', '.join(SIGNALS)}")
            channels.append(Channel(axis, str(signal)))
        window = _number(doc, "window_s", 1.0)
        if not MIN_WINDOW_S <= window <= MAX_WINDOW_S:
            raise ValueError(f"window {window} s: {MIN_WINDOW_S}..{MAX_WINDOW_S} s")
        mode = str(doc.get("mode", "auto"))
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}: one of {', '.join(MODES)}")
        try:
            edge = Edge(str(doc.get("edge", "rising")))
        except ValueError:
            raise ValueError(f"edge {doc.get('edge')!r}: rising, falling or either") from None
        trig_ch = int(_number(doc, "trigger_channel", 0))
        if not 0 <= trig_ch < len(channels):
            raise ValueError(f"trigger channel {trig_ch}: 0..{len(channels) - 1}")
        width = int(_number(doc, "width", 1000))
        width = max(WIDTH_RANGE[0], min(WIDTH_RANGE[1], width))
        trigger = TriggerSettings(mode=mode, edge=edge, level=_number(doc, "level", 0.0),
                                  pre=_number(doc, "pre", 0.1), window_s=window)
        return cls(tuple(channels), trigger, trig_ch, width)


def _number(doc: Mapping[str, object], key: str, default: float) -> float:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, got {value!r}")
    return float(value)


class ScopeSession:
    def __init__(self, samplers: Mapping[int, AxisSampler], send_bytes: SendBytes,
                 send_json: SendJson) -> None:
        self.samplers = samplers
        self.send_bytes, self.send_json = send_bytes, send_json
        self.settings: ScopeSettings | None = None
        self.running = True
        self.seq = 0
        self._tokens: dict[int, int] = {}
        self._groups: dict[int, list[str]] = {}
        self._decimators: dict[int, RollingDecimator] = {}
        self._grid: tuple[int, bool, float] = (0, False, 0.0)  # buckets, pairs, rate used
        self._tracker: TriggerTracker | None = None
        self._pending: float | None = None
        self._last_capture = 0.0
        self._unacked: dict[int, tuple[float, float]] = {}  # seq -> (newest sample, sent)
        self.latencies: deque[float] = deque(maxlen=300)
        #: (sequence, newest sample's time, ack time) of the last frames the page drew.
        self.drawn: deque[tuple[int, float, float]] = deque(maxlen=2000)
        self._acks: deque[float] = deque()
        self.last_window: tuple[float, float, float] | None = None  # t_start, t_end, t_ref
        self.last_flags = 0

    # ------------------------------------------------------------- control
    def configure(self, settings: ScopeSettings) -> None:
        self.close()
        self.settings = settings
        groups: dict[int, list[str]] = {}
        for ch in settings.channels:
            names = groups.setdefault(ch.axis, [])
            if ch.signal not in names:
                names.append(ch.signal)
        self._groups = groups
        for axis, names in groups.items():
            self._tokens[axis] = self.samplers[axis].subscribe(names)
        self._decimators.clear()
        self._grid = (0, False, -1.0)
        trig = settings.channels[settings.trigger_channel]
        self._tracker = TriggerTracker(self._raw_trigger(settings.trigger, trig),
                                       self.samplers[trig.axis].ring, trig.signal)
        self._pending = None
        self._last_capture = -math.inf  # auto mode rolls at once, until a first trigger
        self._unacked.clear()

    def scale(self, channel: Channel) -> tuple[str, float]:
        """A channel's shown unit and the factor from its raw samples (counts, rpm) to it:
        the axis's own unit (issue 33, servobus.gui.fleet.Units)."""
        units = self.samplers[channel.axis].handle.units()
        return units.signal(channel.signal, SIGNALS[channel.signal].unit)

    def _raw_trigger(self, trigger: TriggerSettings, channel: Channel) -> TriggerSettings:
        """The level the page typed in the channel's shown unit, in its raw samples' unit
        (a trigger at 75 mm fires at 75 mm); a negative factor (``direction = -1``) turns
        a rising edge into a falling one."""
        _, factor = self.scale(channel)
        if factor == 1.0:
            return trigger
        edge = trigger.edge
        if factor < 0 and edge is not Edge.EITHER:
            edge = Edge.FALLING if edge is Edge.RISING else Edge.RISING
        return dataclasses.replace(trigger, level=trigger.level / factor, edge=edge)

    def close(self) -> None:
        for axis, token in self._tokens.items():
            self.samplers[axis].unsubscribe(token)
        self._tokens.clear()

    def set_running(self, running: bool) -> None:
        if running and not self.running:
            self.rearm()
        self.running = running

    def rearm(self) -> None:
        if self._tracker is not None:
            self._tracker.rearm()
        self._pending = None
        self._last_capture = -math.inf

    def ack(self, seq: int) -> None:
        entry = self._unacked.pop(seq, None)
        if entry is None:
            return
        now = time.monotonic()
        self.latencies.append(now - entry[0])
        self.drawn.append((seq, entry[0], now))
        self._acks.append(now)

    # ------------------------------------------------------------- loop
    async def run(self) -> None:
        next_state = 0.0
        while True:
            await asyncio.sleep(FRAME_INTERVAL_S)
            now = time.monotonic()
            if self.settings is not None and self.running:
                frame = self.next_frame(now)
                if frame is not None:
                    await self.send_bytes(frame.encode())
            if now >= next_state:
                next_state = now + STATE_INTERVAL_S
                await self.send_json(self.state())

    def _rate(self) -> float:
        rates = [self.samplers[a].rate_hz for a in self._groups]
        return min(rates) if rates and all(r > 0 for r in rates) else 0.0

    def _awaiting_ack(self, now: float) -> bool:
        for seq, (_, sent) in list(self._unacked.items()):
            if now - sent > ACK_GIVE_UP_S:
                del self._unacked[seq]
        return len(self._unacked) >= MAX_IN_FLIGHT

    def next_frame(self, now: float) -> frames.ScopeFrame | None:
        """The frame to send now, if any (also advances the trigger)."""
        s = self.settings
        if s is None or self._awaiting_ack(now):
            return None
        mode = s.trigger.mode
        if mode != "roll":
            frame = self._triggered_frame(now)
            if frame is not None:
                return frame
        if mode == "roll" or (mode == "auto" and
                              now - self._last_capture > s.window_s + AUTO_GRACE_S):
            return self._roll_frame(now, free_run=mode == "auto")
        return None

    # ------------------------------------------------------------- frames
    def _buckets(self) -> tuple[int, bool]:
        s = self.settings
        assert s is not None
        rate = self._rate()
        nb = bucket_count(s.window_s, rate, s.width_px)
        return nb, use_pairs(s.window_s, rate, nb)

    def _frame(self, x: Sequence[float], ys: list[Sequence[float]], t_ref: float,
               newest: float, raw: int, flags: int, now: float, t_start: float, t_end: float
               ) -> frames.ScopeFrame:
        self.seq += 1
        self._unacked[self.seq] = (t_ref + newest, now)
        self.last_window = (t_start, t_end, t_ref)
        self.last_flags = flags
        return frames.ScopeFrame(t_ref=t_ref, rate_hz=self._rate(), seq=self.seq,
                                 raw_count=raw, newest=newest, sent=now, flags=flags,
                                 x=x, ys=ys)

    def _ordered(self, per_axis: Mapping[int, Mapping[str, Sequence[float]]]
                 ) -> list[Sequence[float]]:
        s = self.settings
        assert s is not None
        out: list[Sequence[float]] = []
        for ch in s.channels:
            values = per_axis[ch.axis][ch.signal]
            factor = self.scale(ch)[1]
            # into the frame's float32 array at once (map over a bound method: C speed;
            # 8 channels x 2,000 points x 40 frames/s is 640,000 products a second)
            out.append(values if factor == 1.0 else array("f", map(factor.__mul__, values)))
        return out

    def _roll_frame(self, now: float, *, free_run: bool) -> frames.ScopeFrame | None:
        s = self.settings
        assert s is not None
        nb, pairs = self._buckets()
        rate = self._rate()
        old_nb, old_pairs, old_rate = self._grid
        # A new grid when the rate is first known or moves by a fifth (a polled rate jitters):
        # the buckets may stay while min/max pairs start (a 2 s window of 400 px is 400
        # buckets at 0 Hz and at 4 kHz), so the pairs count as much as the buckets.
        if not self._decimators or ((nb, pairs) != (old_nb, old_pairs)
                                    and abs(rate - old_rate) > 0.2 * old_rate):
            dt = s.window_s / nb
            self._decimators = {a: RollingDecimator(self.samplers[a].ring, names, dt, pairs, nb)
                                for a, names in self._groups.items()}
            self._grid = (nb, pairs, rate)
        nb, pairs, _ = self._grid
        dt = s.window_s / nb
        ends: dict[int, int] = {}
        for axis, dec in self._decimators.items():
            k = dec.update()
            if k is not None:
                ends[axis] = k
        if not ends:
            return None
        newest_end = max(ends.values())
        live = [k for k in ends.values() if (newest_end - k) * dt <= LATE_AXIS_S]
        k_end = min(live)
        k0 = k_end - nb
        t_ref = k_end * dt
        per_axis: dict[int, Mapping[str, Sequence[float]]] = {}
        x: Sequence[float] = ()
        for axis, dec in self._decimators.items():
            cols: Columns = dec.window(k0, k_end)
            x, ys = assemble(cols, dec.names, -nb * dt, dt, nb, pairs)
            per_axis[axis] = ys
        newest = -math.inf
        raw = 0
        for axis in self._decimators:
            ring = self.samplers[axis].ring
            i = ring.index_at(t_ref)
            if i > ring.base:
                newest = max(newest, ring.time(i - 1) - t_ref)
            raw += i - ring.index_at(k0 * dt)
        if newest == -math.inf:
            return None
        flags = (frames.FLAG_PAIRS if pairs else 0) | (frames.FLAG_FREE_RUN if free_run else 0)
        return self._frame(x, self._ordered(per_axis), t_ref, newest, raw, flags, now,
                           k0 * dt, t_ref)

    def _triggered_frame(self, now: float) -> frames.ScopeFrame | None:
        s = self.settings
        assert s is not None and self._tracker is not None
        if self._pending is None:
            self._pending = self._tracker.poll()
        if self._pending is None:
            return None
        t_trig = self._pending
        t_start, t_end = t_trig - s.trigger.pre_s, t_trig + s.trigger.post_s
        behind = [a for a in self._groups
                  if (self.samplers[a].ring.last_time or -math.inf) < t_end]
        if behind and now - t_end < LATE_AXIS_S:
            return None
        nb, pairs = self._buckets()
        per_axis: dict[int, Mapping[str, Sequence[float]]] = {}
        x: Sequence[float] = ()
        raw = 0
        for axis, names in self._groups.items():
            d = decimate_window(self.samplers[axis].ring, names, t_start, t_end, nb, pairs,
                                t_ref=t_trig)
            x = d.x
            per_axis[axis] = d.ys
            raw += d.raw_count
        self._pending = None
        self._last_capture = now
        flags = (frames.FLAG_TRIGGERED | (frames.FLAG_PAIRS if pairs else 0)
                 | (frames.FLAG_HOLDING if self._tracker.done else 0))
        return self._frame(x, self._ordered(per_axis), t_trig, s.trigger.post_s, raw, flags,
                           now, t_start, t_end)

    # ------------------------------------------------------------- reporting
    def state(self) -> dict[str, object]:
        now = time.monotonic()
        while self._acks and self._acks[0] < now - 1.0:
            self._acks.popleft()
        lat = sorted(self.latencies)
        s = self.settings
        return {
            "type": "scope_state", "running": self.running, "frames": self.seq,
            "mode": s.trigger.mode if s else None,
            "holding": bool(self._tracker and self._tracker.done),
            "waiting": bool(s and s.trigger.mode != "roll" and self._pending is None
                            and not (self._tracker and self._tracker.done)),
            "rate_hz": self._rate(), "drawn_per_s": len(self._acks),
            "latency_ms": None if not lat else {
                "median": 1000 * statistics.median(lat),
                "p95": 1000 * lat[min(len(lat) - 1, int(0.95 * len(lat)))],
                "max": 1000 * lat[-1]},
            "sources": [self.samplers[a].describe() for a in self._groups],
        }

    def csv(self) -> str:
        """The raw samples of the frame on screen: per axis a time column (s from x = 0)
        and its signals; rows are sample numbers (axes may differ in rate)."""
        if self.last_window is None or self.settings is None:
            raise ValueError("no frame yet: start the scope first")
        t_start, t_end, t_ref = self.last_window
        columns: list[tuple[str, list[float]]] = []
        for axis, names in self._groups.items():
            ring = self.samplers[axis].ring
            i0, i1 = ring.index_at(t_start), ring.index_at(t_end)
            i0 = max(i0, i1 - CSV_MAX_ROWS)
            handle = self.samplers[axis].handle  # a machine axis by its name: x.t_s
            m = handle.machine_axis
            title = m.name if m is not None and handle.named else f"axis{axis}"
            columns.append((f"{title}.t_s", [t - t_ref for t in ring.time_slice(i0, i1)]))
            for name in names:
                unit, factor = self.scale(Channel(axis, name))
                columns.append((f"{title}.{name}_{unit.replace('/', '_per_')}",
                                [v * factor for v in ring.column(name, i0, i1)]))
        out = io.StringIO()
        out.write(",".join(name for name, _ in columns) + "\n")
        rows = max((len(values) for _, values in columns), default=0)
        for r in range(rows):
            out.write(",".join(_cell(values, r) for _, values in columns) + "\n")
        return out.getvalue()


def _cell(values: list[float], r: int) -> str:
    if r >= len(values) or math.isnan(values[r]):
        return ""
    return repr(values[r])
