"""Which Sparkplug DCMD writes may run: the rules of the MQTT JSON commands, for protobuf.

Decisions (docs/gateway.md "Sparkplug B"): a DCMD writes exactly one of the device's
``Commands/...`` metrics (a Double value, or Boolean true for the commands without one;
``Commands/SetSpeedTtl`` may go with ``Commands/SetSpeed``). The command then runs as any
OPC UA method or MQTT command does (servobus.gateway.commands: the gateway's broker user,
the axis limits, an offline axis refused). Refused, never run:

* a retained DCMD (the broker would replay it to every new subscription);
* the same payload bytes seen before (a QoS 1 redelivery after a reconnect): remembered,
  by digest, for ``2 x max_age``; at most :data:`~servobus.gateway.mqtt_gate.MAX_IDS`;
* a payload timestamp (milliseconds, the Sparkplug payload's own) older than ``max_age``
  or more than :data:`~servobus.gateway.mqtt_gate.MAX_FUTURE_S` ahead; a motion command
  (MOTION) without one;
* a payload larger than :data:`MAX_PAYLOAD` bytes or not a Sparkplug payload.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import OrderedDict
from typing import Any

from google.protobuf.message import DecodeError

from servobus.gateway.commands import MOTION, Command, Refused
from servobus.gateway.mqtt_gate import DEFAULT_MAX_AGE_S, MAX_FUTURE_S, MAX_IDS
from servobus.gateway.sparkplug.payload import BOOLEAN, COMMAND_METRICS, DOUBLE, TTL_METRIC
from servobus.gateway.sparkplug.schema import Payload

MAX_PAYLOAD = 4096
#: the owner of a set_speed lease started by a DCMD (Sparkplug does not say who wrote)
OWNER = "sparkplug"


class DcmdGate:
    def __init__(self, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        self.max_age_s = max_age_s
        self._seen: OrderedDict[bytes, float] = OrderedDict()

    def admit(self, axis: str, data: bytes, retained: bool,
              now: float | None = None) -> Command:
        """The command to run, or Refused with the reason."""
        now = time.time() if now is None else now
        if retained:
            raise Refused("BadRequestNotAllowed", "a retained DCMD is never run")
        if len(data) > MAX_PAYLOAD:
            raise Refused("BadRequestTooLarge", f"a DCMD has at most {MAX_PAYLOAD} bytes")
        try:
            message: Any = Payload.FromString(data)
        except DecodeError as exc:
            raise Refused("BadDecodingError", f"not a Sparkplug B payload: {exc}") from None
        command, ttl = None, None
        for metric in message.metrics:
            if metric.name == TTL_METRIC:
                ttl = _double(metric)
            elif metric.name in COMMAND_METRICS:
                if command is not None:
                    raise Refused("BadInvalidArgument", "one Commands/... metric per DCMD")
                command = metric
            else:
                raise Refused("BadMethodInvalid",
                              f"{metric.name!r} is not a command metric of this device "
                              f"({', '.join(COMMAND_METRICS)})")
        if command is None:
            raise Refused("BadMethodInvalid", "the DCMD writes no Commands/... metric")
        name, kind = COMMAND_METRICS[command.name]
        value = None
        if kind == DOUBLE:
            value = _double(command)
        elif not (command.datatype in (0, BOOLEAN) and command.HasField("boolean_value")
                  and command.boolean_value):
            raise Refused("BadInvalidArgument", f"{command.name}: write Boolean true to run it")
        if ttl is not None and name != "set_speed":
            raise Refused("BadInvalidArgument", f"{TTL_METRIC} goes with Commands/SetSpeed")
        self._check_time(message, name, now)
        self._remember(data, now)
        return Command(axis, name, value, ttl)

    def _check_time(self, message: Any, name: str, now: float) -> None:
        if not message.HasField("timestamp"):
            if name in MOTION:
                raise Refused("BadInvalidArgument", f"{name} needs the payload's timestamp")
            return
        sent = message.timestamp / 1000.0
        if now - sent > self.max_age_s:
            raise Refused("BadInvalidTimestamp",
                          f"stale: sent {now - sent:.1f} s ago (at most {self.max_age_s:g} s)")
        if sent - now > MAX_FUTURE_S:
            raise Refused("BadInvalidTimestamp",
                          f"timestamp {sent - now:.1f} s in the future: check the sender's "
                          "clock")

    def _remember(self, data: bytes, now: float) -> None:
        horizon = now - 2 * self.max_age_s
        while self._seen:
            oldest, when = next(iter(self._seen.items()))
            if when >= horizon:
                break
            del self._seen[oldest]
        digest = hashlib.sha256(data).digest()
        if digest in self._seen:
            raise Refused("BadRequestNotAllowed", "this DCMD was seen before: not re-run")
        if len(self._seen) >= MAX_IDS:
            raise Refused("BadTooManyOperations", "too many commands: try again later")
        self._seen[digest] = now


def _double(metric: Any) -> float:
    if metric.datatype not in (0, DOUBLE) or not metric.HasField("double_value") \
            or not math.isfinite(metric.double_value):
        raise Refused("BadInvalidArgument", f"{metric.name} is a finite Double")
    return float(metric.double_value)
