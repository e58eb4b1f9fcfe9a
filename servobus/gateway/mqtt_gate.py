"""Which MQTT commands may run: never a retained one, a repeated id, or a stale one.

Decisions (docs/gateway.md "MQTT commands"): a command is a JSON object
``{"id": "...", "ts": <unix seconds>, "cmd": "move_relative", "value": 1.5}``. A motion
command (MOTION, ``ack`` included: it allows motion again after a possible power loss)
must carry ``id`` (1-128 characters) and ``ts``; a stop may leave them out. Refused, never
run, and answered on ``.../reply``:

* a retained message (the broker would replay it to every new subscription);
* an id seen before (QoS 1 redelivers a message after a reconnect) - ids are remembered
  for ``2 x max_age``, longer than any command is accepted, so a repeat is always caught;
  when :data:`MAX_IDS` are remembered new commands are refused until old ids expire
  (bounded memory: more than 10,000 commands in 10 s is not a control program);
* ``ts`` older than ``max_age`` (default 5 s) or more than :data:`MAX_FUTURE_S` ahead of
  this computer's clock (the sender's clock must be synchronised, NTP);
* a payload that is not such an object, or larger than :data:`MAX_PAYLOAD` bytes, nested
  deeper than 32 levels or holding a number beyond a double's range (servobus.bounded_json).

The retained, size, age and seen-before checks are servobus.gateway.gate_core, shared with
the Sparkplug DCMD writes; this module decodes and checks the JSON.

``set_speed`` is a lease (docs/gateway.md "MQTT commands"): it takes ``ttl`` (seconds,
default 0.5, above 0 and at most 1; BadOutOfRange beyond, checked with the OPC UA
arguments in servobus.gateway.commands) and ends that long after the last ``set_speed``
unless another one (a new ``id``, a fresh ``ts``) renews it. The lease's owner: MQTT does
not tell a subscriber who published, so a command may name its sender in ``client``
(1-64 characters); the owner is ``mqtt:<client>``, or ``mqtt`` for commands without one
(all such senders share one owner: they renew each other's motion).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from servobus import bounded_json
from servobus.errors import JsonRefused
from servobus.gateway.commands import AXIS_COMMANDS, MOTION, Command, Refused
from servobus.gateway.gate_core import DEFAULT_MAX_AGE_S as DEFAULT_MAX_AGE_S
from servobus.gateway.gate_core import MAX_FUTURE_S as MAX_FUTURE_S
from servobus.gateway.gate_core import MAX_IDS as MAX_IDS
from servobus.gateway.gate_core import MAX_PAYLOAD as MAX_PAYLOAD
from servobus.gateway.gate_core import GateCore
from servobus.machine.lease import DEFAULT_TTL_S

MAX_CLIENT = 64


@dataclass(frozen=True)
class Accepted:
    command: Command
    id: str | None
    owner: str = "mqtt"  # who holds a set_speed lease: mqtt:<client>, or mqtt


class CommandGate:
    def __init__(self, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        self.core = GateCore("command", max_age_s)

    def admit(self, axis: str, payload: bytes, retained: bool,
              now: float | None = None) -> Accepted:
        """The command to run, or Refused with the reason."""
        now = time.time() if now is None else now
        self.core.check_frame(payload, retained)
        try:  # nesting and numbers bounded (servobus.bounded_json): nothing here can overflow
            data = bounded_json.loads(payload)
        except JsonRefused as exc:
            raise Refused("BadDecodingError", f"a command is a JSON object: {exc}") from None
        if not isinstance(data, dict):
            raise Refused("BadDecodingError", "a command is a JSON object")
        name = data.get("cmd")
        if not isinstance(name, str) or name not in AXIS_COMMANDS:
            raise Refused("BadMethodInvalid",
                          f"cmd must be one of {', '.join(sorted(AXIS_COMMANDS))}")
        ident, ts = data.get("id"), data.get("ts")
        if ident is not None and (not isinstance(ident, str) or not 1 <= len(ident) <= 128):
            raise Refused("BadInvalidArgument", "id is a string of 1..128 characters")
        if name in MOTION and (ident is None or ts is None):
            raise Refused("BadInvalidArgument", f"{name} needs an id and a timestamp ts")
        if ts is not None:
            if isinstance(ts, bool) or not isinstance(ts, int | float) or not math.isfinite(ts):
                raise Refused("BadInvalidArgument", "ts is a number: unix time in seconds")
            self.core.check_age(ts, now, "ts is")
        value = data.get("value")
        if AXIS_COMMANDS[name] and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise Refused("BadInvalidArgument", f"{name} needs a number value")
        ttl = data.get("ttl")
        if ttl is not None and (isinstance(ttl, bool) or not isinstance(ttl, int | float)):
            raise Refused("BadInvalidArgument", "ttl is a number of seconds")
        if ttl is None and name == "set_speed":
            ttl = DEFAULT_TTL_S
        client = data.get("client")
        if client is not None and (not isinstance(client, str)
                                   or not 1 <= len(client) <= MAX_CLIENT):
            raise Refused("BadInvalidArgument",
                          f"client is a string of 1..{MAX_CLIENT} characters")
        if ident is not None:
            self.core.remember(ident, now, f"id {ident!r}")
        # a value on a command that takes none is ignored: a stop runs whatever it carries
        number = float(value) if AXIS_COMMANDS[name] and value is not None else None
        command = Command(axis, name, number,
                          None if ttl is None else float(ttl))
        return Accepted(command, ident, "mqtt" if client is None else f"mqtt:{client}")
