"""Which Sparkplug DCMD writes may run: the rules of the MQTT JSON commands, for protobuf.

Decisions (docs/gateway.md "Sparkplug B"): a DCMD writes exactly one of the device's
``Commands/...`` metrics (a Double value, or Boolean true for the commands without one;
``Commands/SetSpeedTtl`` may go with ``Commands/SetSpeed``). The command then runs as any
OPC UA method or MQTT command does (servobus.gateway.commands: the gateway's broker user,
the axis limits, an offline axis refused). Refused, never run:

* a retained DCMD (the broker would replay it to every new subscription);
* the same payload bytes seen before (a QoS 1 redelivery after a reconnect): remembered,
  by digest, for ``2 x max_age``; at most :data:`~servobus.gateway.gate_core.MAX_IDS`;
* a payload timestamp (milliseconds, the Sparkplug payload's own) older than ``max_age``
  or more than :data:`~servobus.gateway.gate_core.MAX_FUTURE_S` ahead; a motion command
  (MOTION) without one;
* a payload larger than :data:`~servobus.gateway.gate_core.MAX_PAYLOAD` bytes or not a
  Sparkplug payload.

The retained, size, age and seen-before checks are the JSON commands' own
(servobus.gateway.gate_core); this module decodes the protobuf payload.
"""

from __future__ import annotations

import hashlib
import math
import time
from typing import Any

from google.protobuf.message import DecodeError

from servobus.gateway.commands import MOTION, Command, Refused
from servobus.gateway.gate_core import DEFAULT_MAX_AGE_S, GateCore
from servobus.gateway.sparkplug.payload import BOOLEAN, COMMAND_METRICS, DOUBLE, TTL_METRIC
from servobus.gateway.sparkplug.schema import Payload

#: the owner of a set_speed lease started by a DCMD (Sparkplug does not say who wrote)
OWNER = "sparkplug"


class DcmdGate:
    def __init__(self, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        self.core = GateCore("DCMD", max_age_s)

    def admit(self, axis: str, data: bytes, retained: bool,
              now: float | None = None) -> Command:
        """The command to run, or Refused with the reason."""
        now = time.time() if now is None else now
        self.core.check_frame(data, retained)
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
        self.core.remember(hashlib.sha256(data).digest(), now, "this DCMD")
        return Command(axis, name, value, ttl)

    def _check_time(self, message: Any, name: str, now: float) -> None:
        if not message.HasField("timestamp"):
            if name in MOTION:
                raise Refused("BadInvalidArgument", f"{name} needs the payload's timestamp")
            return
        self.core.check_age(message.timestamp / 1000.0, now, "timestamp")


def _double(metric: Any) -> float:
    if metric.datatype not in (0, DOUBLE) or not metric.HasField("double_value") \
            or not math.isfinite(metric.double_value):
        raise Refused("BadInvalidArgument", f"{metric.name} is a finite Double")
    return float(metric.double_value)
