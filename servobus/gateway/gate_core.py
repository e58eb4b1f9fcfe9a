"""The checks every MQTT command path makes, whatever its payload's format.

Two decoders call it: the JSON commands (servobus.gateway.mqtt_gate) and the Sparkplug
DCMD writes (servobus.gateway.sparkplug.commands). Each decodes its own payload; this core
refuses, before decoding, a retained message (the broker would replay it to every new
subscription) and one larger than :data:`MAX_PAYLOAD`; after decoding, a send time older
than ``max_age`` or more than :data:`MAX_FUTURE_S` ahead; last, a command seen before
(a QoS 1 redelivery after a reconnect). What was seen is remembered for ``2 x max_age``,
longer than any command is accepted, so a repeat is always caught; when :data:`MAX_IDS`
are remembered new commands are refused until old ones expire (bounded memory).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable

from servobus.gateway.commands import Refused

MAX_PAYLOAD = 4096
MAX_IDS = 10_000
MAX_FUTURE_S = 2.0
DEFAULT_MAX_AGE_S = 5.0


class GateCore:
    """``what`` names a command in the refusals ("command", "DCMD")."""

    def __init__(self, what: str, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        self.what = what
        self.max_age_s = max_age_s
        self._seen: OrderedDict[Hashable, float] = OrderedDict()

    def check_frame(self, payload: bytes, retained: bool) -> None:
        """Before decoding: never a retained message, nor one over MAX_PAYLOAD bytes."""
        if retained:
            raise Refused("BadRequestNotAllowed", f"a retained {self.what} is never run")
        if len(payload) > MAX_PAYLOAD:
            raise Refused("BadRequestTooLarge",
                          f"a {self.what} has at most {MAX_PAYLOAD} bytes")

    def check_age(self, sent: float, now: float, stamp: str) -> None:
        """``sent`` (unix seconds) neither stale nor ahead of this clock; ``stamp`` names
        the payload's time in the refusal ("ts is", "timestamp")."""
        if now - sent > self.max_age_s:
            raise Refused("BadInvalidTimestamp",
                          f"stale: sent {now - sent:.1f} s ago (at most {self.max_age_s:g} s)")
        if sent - now > MAX_FUTURE_S:
            raise Refused("BadInvalidTimestamp",
                          f"{stamp} {sent - now:.1f} s in the future: check the sender's clock")

    def remember(self, key: Hashable, now: float, named: str) -> None:
        """Last: refuses ``key`` seen before (``named`` in the refusal), or any when full."""
        horizon = now - 2 * self.max_age_s
        while self._seen:
            oldest, when = next(iter(self._seen.items()))
            if when >= horizon:
                break
            del self._seen[oldest]
        if key in self._seen:
            raise Refused("BadRequestNotAllowed", f"{named} was seen before: not re-run")
        if len(self._seen) >= MAX_IDS:
            raise Refused("BadTooManyOperations", "too many commands: try again later")
        self._seen[key] = now
