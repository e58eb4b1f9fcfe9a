"""Sparkplug B topics and payloads of one gateway: the edge node is the gateway, each axis a
device (docs/gateway.md "Sparkplug B").

Device metrics (the DBIRTH carries them all, with their datatype and value; a DDATA only
those that changed since the last message, report by exception)::

    Position, Speed, Current   Double, property engUnit: the axis unit, its unit per second, A
    Enabled, Moving, InPosition  Boolean
    Alarm/Code (Int32), Alarm/Text (String)
    Good (Boolean), Error (String)   whether the readings above are valid; while not, they
                                     are sent with is_null, and Error says why
    Online, PowerLost (Boolean), PowerLostReason, Interrupted (String)  the link's health
    Commands/MoveAbsolute, Commands/MoveRelative, Commands/SetSpeed, Commands/SetSpeedTtl
                               Double, written by DCMD (servobus.gateway.sparkplug.commands)
    Commands/Stop, Commands/Enable, Commands/Disable, Commands/ResetAlarm,
    Commands/Acknowledge       Boolean, written true by DCMD
    Commands/Result, Commands/Error  String: the last DCMD's status code name and reason

The node's NBIRTH: ``bdSeq`` (UInt64), ``Node Control/Rebirth`` (Boolean, false), and
``Node Info/Machine``, ``Node Info/Version`` (String).
"""

from __future__ import annotations

import math
import time
from typing import Any

from servobus import __version__
from servobus.gateway.sampler import Sample
from servobus.gateway.source import MachineAxis
from servobus.gateway.sparkplug.schema import DATA_TYPES, Payload

NAMESPACE = "spBv1.0"
BD_SEQ = "bdSeq"
REBIRTH = "Node Control/Rebirth"
#: seq and bdSeq count 0..255 and wrap
SEQ_MODULO = 256
UNIT_PROPERTY = "engUnit"

DOUBLE, BOOLEAN, STRING = DATA_TYPES["Double"], DATA_TYPES["Boolean"], DATA_TYPES["String"]
INT32, UINT64 = DATA_TYPES["Int32"], DATA_TYPES["UInt64"]

#: command metric -> (command name, datatype); Commands/SetSpeedTtl goes with SetSpeed
COMMAND_METRICS: dict[str, tuple[str, int]] = {
    "Commands/MoveAbsolute": ("move_absolute", DOUBLE),
    "Commands/MoveRelative": ("move_relative", DOUBLE),
    "Commands/SetSpeed": ("set_speed", DOUBLE),
    "Commands/Stop": ("stop", BOOLEAN),
    "Commands/Enable": ("enable", BOOLEAN),
    "Commands/Disable": ("disable", BOOLEAN),
    "Commands/ResetAlarm": ("reset_alarm", BOOLEAN),
    "Commands/Acknowledge": ("ack", BOOLEAN),
}
TTL_METRIC = "Commands/SetSpeedTtl"
RESULT, RESULT_ERROR = "Commands/Result", "Commands/Error"
#: the readings a Bad sample sends as null
READINGS = ("Position", "Speed", "Current", "Enabled", "Moving", "InPosition", "Alarm/Code",
            "Alarm/Text")

Value = bool | int | float | str | None
Metrics = dict[str, tuple[int, Value]]


def topic(group: str, kind: str, node: str, device: str | None = None) -> str:
    return "/".join([NAMESPACE, group, kind, node, *([device] if device else [])])


def now_ms() -> int:
    return int(time.time() * 1000)


def units(axis: MachineAxis) -> dict[str, str]:
    return {"Position": axis.unit, "Speed": axis.speed_unit, "Current": "A"}


def device_metrics(sample: Sample | None) -> Metrics:
    """The axis's metrics (commands aside) from its latest sample (None: none yet)."""
    good = sample is not None and sample.ok
    st = sample.status if sample is not None else None

    def num(x: float | None) -> float | None:
        return x if good and x is not None and math.isfinite(x) else None

    out: Metrics = {
        "Position": (DOUBLE, num(sample.position if sample else None)),
        "Speed": (DOUBLE, num(sample.speed if sample else None)),
        "Current": (DOUBLE, num(sample.current if sample else None)),
        "Enabled": (BOOLEAN, st.enabled if good and st else None),
        "Moving": (BOOLEAN, st.moving if good and st else None),
        "InPosition": (BOOLEAN, st.in_position if good and st else None),
        "Alarm/Code": (INT32, st.alarm_code if good and st else None),
        "Alarm/Text": (STRING, st.alarm_text if good and st else None),
        "Good": (BOOLEAN, good),
        "Error": (STRING, "" if good else (sample.error if sample else "no sample yet")),
    }
    h = sample.health if sample is not None else None
    out.update({
        "Online": (BOOLEAN, h.online if h else None),
        "PowerLost": (BOOLEAN, h.power_lost if h else None),
        "PowerLostReason": (STRING, (h.power_lost_reason or "") if h else None),
        "Interrupted": (STRING, (h.interrupted or "") if h else None),
    })
    return out


def command_metrics(result: str = "", error: str = "") -> Metrics:
    out: Metrics = {name: (kind, 0.0 if kind == DOUBLE else False)
                    for name, (_, kind) in COMMAND_METRICS.items()}
    out[TTL_METRIC] = (DOUBLE, 0.0)
    out[RESULT] = (STRING, result)
    out[RESULT_ERROR] = (STRING, error)
    return out


def set_value(metric: Any, kind: int, value: Value) -> None:
    metric.datatype = kind
    if value is None:
        metric.is_null = True
    elif kind == DOUBLE:
        metric.double_value = float(value)
    elif kind == BOOLEAN:
        metric.boolean_value = bool(value)
    elif kind == STRING:
        metric.string_value = str(value)
    elif kind == INT32:  # Sparkplug carries Int32 in int_value as two's complement
        metric.int_value = int(value) & 0xFFFFFFFF
    else:
        metric.long_value = int(value)


def payload(metrics: Metrics, seq: int | None, stamp: int | None = None,
            unit_of: dict[str, str] | None = None) -> Any:
    """A Payload with ``metrics`` (names always: servobus uses no aliases)."""
    stamp = now_ms() if stamp is None else stamp
    out = Payload(timestamp=stamp)
    if seq is not None:
        out.seq = seq
    for name, (kind, value) in metrics.items():
        metric = out.metrics.add(name=name, timestamp=stamp)
        set_value(metric, kind, value)
        unit = (unit_of or {}).get(name)
        if unit is not None:
            metric.properties.keys.append(UNIT_PROPERTY)
            metric.properties.values.add(type=STRING, string_value=unit)
    return out


def node_birth(bd_seq: int, machine: str) -> Any:
    return payload({BD_SEQ: (UINT64, bd_seq), REBIRTH: (BOOLEAN, False),
                    "Node Info/Machine": (STRING, machine),
                    "Node Info/Version": (STRING, __version__)}, 0)


def node_death(bd_seq: int) -> bytes:
    """The NDEATH: bdSeq only (no seq), the will of the connection with that bdSeq."""
    return bytes(payload({BD_SEQ: (UINT64, bd_seq)}, None).SerializeToString())


def metric_value(metric: Any) -> Value:
    """A decoded metric's value as Python (None when null or of another datatype)."""
    if metric.is_null:
        return None
    which = metric.WhichOneof("value")
    return None if which is None else getattr(metric, which)
