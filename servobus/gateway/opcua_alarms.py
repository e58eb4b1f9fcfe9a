"""Drive alarms as OPC UA conditions (Part 9): one AxisAlarmConditionType per axis.

Decisions (issue 36, docs/gateway.md "Alarms"):

* AxisAlarmConditionType (servobus namespace) is an AlarmConditionType with the family's
  ``AlarmCode`` and ``AlarmText`` and the ``AxisName``. Each axis holds its condition
  object ``Alarm`` (HasComponent and HasCondition, with the type's mandatory members);
  the event's ConditionId is that object, its SourceNode the axis.
* The condition becomes active when the drive reports an alarm code, inactive when the
  code is 0 again (ResetAlarm, or the drive clears it); a new code is a new active alarm,
  unacknowledged. Retain is true while it is active or unacknowledged.
* Every state change is one event, delivered to subscriptions on the axis and on the
  Server object (asyncua delivers an event only to the node that emits it: the gateway
  emits it from both, with one EventId), and kept for ConditionRefresh of either while
  Retain is true (asyncua's table of retained conditions holds the axis's; the Server
  object's copy sits beside it).
* Acknowledge (the condition's method, or AcknowledgeableConditionType's on the condition
  object) runs the gateway's ``ack`` command, the same path as the axis's Acknowledge
  method (a user of the users file; it clears a power-loss flag, nothing is sent to the
  drive). The EventId must be the condition's latest (else BadEventIdUnknown); an
  acknowledged alarm answers BadConditionBranchAlreadyAcked.
"""

from __future__ import annotations

import copy
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from asyncua import Node, Server, ua

HAS_CONDITION = ua.ObjectIds.HasCondition
ACKNOWLEDGE = ua.ObjectIds.AcknowledgeableConditionType_Acknowledge
#: ``ack(axis)``: the gateway's acknowledge path; its status is the method's answer.
Ack = Callable[[str], Awaitable[ua.StatusCode]]


@dataclass
class AxisCondition:
    axis: str
    node: Node
    generator: Any  # asyncua EventGenerator
    code: int = 0
    acked: bool = True


class AxisAlarms:
    """The conditions of a machine's axes; :meth:`update` with each alarm code read."""

    def __init__(self, server: Server, ack: Ack) -> None:
        self.server = server
        self.ack = ack
        self.conditions: dict[str, AxisCondition] = {}
        self._by_node: dict[ua.NodeId, AxisCondition] = {}

    async def build(self, types_ns: int, nodes_ns: int, axes: dict[str, Node]) -> None:
        s = self.server
        etype = await s.create_custom_event_type(
            types_ns, "AxisAlarmConditionType", ua.ObjectIds.AlarmConditionType,
            [("AxisName", ua.VariantType.String), ("AlarmCode", ua.VariantType.Int32),
             ("AlarmText", ua.VariantType.String)])
        for name, axis_node in axes.items():
            node = await axis_node.add_object(
                ua.NodeId(f"{axis_node.nodeid.Identifier}.Alarm", nodes_ns),
                ua.QualifiedName("Alarm", types_ns), etype.nodeid, instantiate_optional=False)
            await axis_node.add_reference(node.nodeid, HAS_CONDITION, forward=True,
                                          bidirectional=True)
            ack = await node.get_child("0:Acknowledge")
            s.link_method(ack, self._acknowledge)
            gen = await s.get_event_generator(etype, axis_node)
            ev = gen.event
            ev.add_property("NodeId", node.nodeid, ua.VariantType.NodeId)  # ConditionId
            ev.ConditionName = "Alarm"
            ev.AxisName = name
            ev.BranchId = ua.NodeId()
            setattr(ev, "EnabledState/Id", True)
            ev.EnabledState = ua.LocalizedText("Enabled")
            cond = AxisCondition(name, node, gen)
            self._set(cond, 0, "", acked=True)
            self.conditions[name] = cond
            self._by_node[node.nodeid] = cond
            # the Server object notifies of the axes' events (Part 3, HasNotifier)
            await s.nodes.server.add_reference(axis_node.nodeid, ua.ObjectIds.HasNotifier,
                                               forward=True, bidirectional=True)
        s.link_method(s.get_node(ua.NodeId(ACKNOWLEDGE)), self._acknowledge)

    async def update(self, axis: str, code: int, text: str) -> str | None:
        """A new alarm code read from ``axis``: the event's message when the condition
        changed (one event sent), else None."""
        cond = self.conditions.get(axis)
        if cond is None or cond.code == code:
            return None
        self._set(cond, code, text, acked=not code)
        return await self._trigger(cond)

    def _set(self, cond: AxisCondition, code: int, text: str, acked: bool) -> None:
        ev = cond.generator.event
        cond.code, cond.acked = code, acked
        ev.AlarmCode, ev.AlarmText = code, text
        setattr(ev, "ActiveState/Id", bool(code))
        ev.ActiveState = ua.LocalizedText("Active" if code else "Inactive")
        setattr(ev, "AckedState/Id", acked)
        ev.AckedState = ua.LocalizedText("Acknowledged" if acked else "Unacknowledged")
        ev.Retain = bool(code) or not acked
        ev.Severity = 800 if code else 100
        ev.Message = ua.LocalizedText(f"axis {cond.axis}: alarm {code} {text}" if code
                                      else f"axis {cond.axis}: alarm cleared")

    async def _trigger(self, cond: AxisCondition) -> str:
        """The event from the axis (asyncua keeps it for ConditionRefresh of subscriptions
        on the axis), then a copy from the Server object, kept beside it for theirs."""
        gen = cond.generator
        await gen.trigger()
        ev = gen.event
        from_server = copy.copy(ev)
        from_server.emitting_node = self.server.nodes.server.nodeid
        service = self.server.iserver.subscription_service
        for sub in list(service.subscriptions.values()):
            await sub.monitored_item_srv.trigger_event(from_server)
        key = (ev.NodeId, "Server")  # asyncua's own entry is keyed by the ConditionId
        if ev.Retain:
            service._conditions[key] = from_server
        else:
            service._conditions.pop(key, None)
        await self._mirror(cond)
        return str(ev.Message.Text)

    async def _mirror(self, cond: AxisCondition) -> None:
        """The condition object's own state variables follow its events."""
        ev = cond.generator.event
        for state in ("ActiveState", "AckedState"):
            node = await cond.node.get_child(f"0:{state}")
            await node.write_value(getattr(ev, state))
            await (await node.get_child("0:Id")).write_value(getattr(ev, f"{state}/Id"))

    async def _acknowledge(self, parent: ua.NodeId, *args: Any) -> ua.StatusCode:
        cond = self._by_node.get(parent)
        if cond is None:
            return ua.StatusCode(ua.StatusCodes.BadMethodInvalid)
        if len(args) < 2:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        if len(args) > 2:
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        event_id = getattr(args[0], "Value", args[0])
        if event_id != cond.generator.event.EventId.Value:
            return ua.StatusCode(ua.StatusCodes.BadEventIdUnknown)
        if cond.acked:
            return ua.StatusCode(ua.StatusCodes.BadConditionBranchAlreadyAcked)
        status = await self.ack(cond.axis)
        if not status.is_good():
            return status
        comment = getattr(args[1], "Value", args[1])
        ev = cond.generator.event
        self._set(cond, cond.code, ev.AlarmText, acked=True)
        if isinstance(comment, ua.LocalizedText):
            ev.Comment = comment
        await self._trigger(cond)
        return status
