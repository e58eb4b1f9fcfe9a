"""The scope's grid in-process, on stand-in samplers: no drive, no clock but the one given."""

from __future__ import annotations

from dataclasses import dataclass, field

from servobus.gui import frames
from servobus.gui.fleet import Units
from servobus.gui.ring import SampleRing
from servobus.gui.scope_session import ScopeSession, ScopeSettings


class Handle:
    """An axis shown in counts and rpm, as a bare drive URL is."""

    def units(self) -> Units:
        return Units()


@dataclass
class Sampler:
    """What a session reads of an axis sampler: its ring and rate, and subscriptions."""

    ring: SampleRing = field(default_factory=lambda: SampleRing(100_000))
    rate_hz: float = 0.0
    handle: Handle = field(default_factory=Handle)

    def subscribe(self, signals: object) -> int:
        return 1

    def unsubscribe(self, token: int) -> None:
        pass

    def fill(self, t0: float, t1: float, rate_hz: float) -> None:
        n = int((t1 - t0) * rate_hz)
        times = [t0 + i / rate_hz for i in range(n)]
        self.ring.extend(times, {"position": [float(i) for i in range(n)],
                                 "speed": [0.0] * n})


async def _nothing(_: object) -> None:
    pass


def test_pairs_start_once_the_second_axis_rate_is_known_though_the_buckets_stay() -> None:
    # The CI failure of test_rolling_scope_streams_the_4khz_trace_and_shows_a_move: axis 1's
    # trace was in while axis 2's rate was still 0, so the first grid was 400 buckets without
    # min/max pairs; at 4 kHz it is 400 buckets with pairs, and the grid must follow.
    one, two = Sampler(rate_hz=4000.0), Sampler()
    session = ScopeSession({1: one, 2: two}, _nothing, _nothing)  # type: ignore[dict-item]
    session.configure(ScopeSettings.parse(
        {"channels": [{"axis": 1, "signal": "position"}, {"axis": 2, "signal": "speed"}],
         "window_s": 2.0, "mode": "roll", "width": 400}, {1, 2}))
    one.fill(0.0, 1.0, 4000.0)
    first = session.next_frame(now=1.0)
    assert first is not None and not first.flags & frames.FLAG_PAIRS
    session.ack(first.seq)
    two.rate_hz = 4000.0
    one.fill(1.0, 1.5, 4000.0)
    two.fill(0.0, 1.5, 4000.0)
    second = session.next_frame(now=1.5)
    assert second is not None and second.flags & frames.FLAG_PAIRS
    assert len(second.x) == 2 * 400
