"""The OPC UA address space of one machine, after OPC 40010-1 (Robotics) and OPC 10000-100 (DI).

Decision (docs/gateway.md "Information model"): the companion specifications' NodeSets are
not imported (they are large, and a client that does not know them gains nothing); the model
is built in code with their browse names in their namespaces, so a client that browses by
the standard names finds what it expects::

    Objects
      DeviceSet                         (DI)
        MotionDeviceSystem              (Robotics)
          MotionDevices                 (Robotics)
            <machine>                   (servobus)   one MotionDevice per machine
              Identification            (DI)         Manufacturer, Model, ProductInstanceUri, ...
              Axes                      (Robotics)
                <axis>                  (servobus)   named as in the machine file
                  ParameterSet          (DI)
                    ActualPosition      (Robotics)   Double, axis unit, EngineeringUnits, EURange
                    ActualSpeed         (Robotics)   Double, axis unit per second
                    ActualCurrent, Enabled, Moving, InPosition, AlarmCode, AlarmText
                                        (servobus)   readings: Bad while they cannot be read
                    Online, LastError, PowerLost, PowerLostReason, Interrupted
                                        (servobus)   the link's health: always Good
                  Identification        (DI)         Manufacturer, Model (family), Protocol,
                                                     DeviceAddress (link and drive id)
                  MoveAbsolute(Double), MoveRelative(Double), SetSpeed(Double, Ttl
                  Double), Stop(), Enable(), Disable(), ResetAlarm(), Acknowledge()
                                        (servobus)
              StopAll()                 (servobus)

Node ids are strings in the gateway's own namespace, ``urn:servobus:gateway:<gateway id>``
(``<machine>.<axis>.ActualPosition``), so they stay the same from one start to the next and
an aggregating server keeps the nodes of many gateways apart; browse names and types live
in the servobus namespace, ``urn:servobus:gateway``, the same in every gateway
(servobus.gateway.identity). Alarms are events of AxisAlarmEventType (servobus namespace,
a BaseEventType) emitted by the axis object; a link going down or coming back is an event
of LinkEventType emitted by the machine object (one per link, not per axis). A method runs
only when called on its own object (its axis, or the machine for StopAll); on any other
object it answers BadMethodInvalid and nothing runs.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from asyncua import Node, Server, ua

from servobus import __version__
from servobus.gateway.identity import TYPES_URI, application_uri
from servobus.gateway.source import Machine, MachineAxis, family_name, family_title
from servobus.gateway.units import eu_information

DI_URI = "http://opcfoundation.org/UA/DI/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
SERVOBUS_URI = TYPES_URI  # browse names and types; node ids: the gateway's own namespace
MANUFACTURER = "servobus"

#: ParameterSet variables of the servobus namespace: name -> (variant type, initial value).
STATE_VARIABLES: dict[str, tuple[ua.VariantType, object]] = {
    "ActualCurrent": (ua.VariantType.Double, math.nan),
    "Enabled": (ua.VariantType.Boolean, False),
    "Moving": (ua.VariantType.Boolean, False),
    "InPosition": (ua.VariantType.Boolean, False),
    "AlarmCode": (ua.VariantType.Int32, 0),
    "AlarmText": (ua.VariantType.String, ""),
}

#: The health of an axis's link (issue 29, docs/gateway.md "Recovery"): name -> variant
#: type. Known to the gateway whether the drive answers or not, so always Good. No
#: "LastGood" (decision): it would change with every sample; a Bad reading carries the time
#: it was last good as its SourceTimestamp.
HEALTH_VARIABLES: dict[str, ua.VariantType] = {
    "Online": ua.VariantType.Boolean,
    "LastError": ua.VariantType.String,
    "PowerLost": ua.VariantType.Boolean,
    "PowerLostReason": ua.VariantType.String,
    "Interrupted": ua.VariantType.String,
}

#: SetSpeed's description: a lease, renewed by calling again (docs/gateway.md "SetSpeed").
SET_SPEED_HELP = ("constant speed in the axis unit per second (0 stops); it ends Ttl seconds "
                  "after the last call unless called again (renew it), and when the session "
                  "closes; on a continuous axis it is open-ended (Ttl is checked, not used)")
TTL_HELP = ("seconds the speed holds after this call, above 0 and at most 1; call again "
            "before it runs out to keep the axis turning")

#: OPC UA method name -> (command name, its Double input arguments as (name, description)).
AXIS_METHODS: dict[str, tuple[str, tuple[tuple[str, str], ...]]] = {
    "MoveAbsolute": ("move_absolute", (("Value", "target position in the axis unit"),)),
    "MoveRelative": ("move_relative", (("Value", "distance in the axis unit"),)),
    "SetSpeed": ("set_speed", (("Value", SET_SPEED_HELP), ("Ttl", TTL_HELP))),
    "Stop": ("stop", ()),
    "Enable": ("enable", ()),
    "Disable": ("disable", ()),
    "ResetAlarm": ("reset_alarm", ()),
    "Acknowledge": ("ack", ()),  # the machine axis's acknowledge(): nothing is sent
}

#: ``handler(axis, command, arguments)``: the method's Double arguments in order.
MethodHandler = Callable[[str, str, tuple[float, ...]], Awaitable[ua.StatusCode]]


@dataclass
class AxisNodes:
    axis: MachineAxis
    node: Node
    variables: dict[str, Node] = field(default_factory=dict)  # readings
    health: dict[str, Node] = field(default_factory=dict)  # HEALTH_VARIABLES


@dataclass
class Namespaces:
    di: int
    robotics: int
    servobus: int  # browse names and types (shared by every gateway)
    nodes: int  # node ids (this gateway's own namespace)


def qn(ns: int, name: str) -> ua.QualifiedName:
    return ua.QualifiedName(name, ns)


async def register_namespaces(server: Server, nodes_uri: str) -> Namespaces:
    return Namespaces(await server.register_namespace(DI_URI),
                      await server.register_namespace(ROBOTICS_URI),
                      await server.register_namespace(SERVOBUS_URI),
                      await server.register_namespace(nodes_uri))


def method_argument(name: str, description: str) -> ua.Argument:
    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(ua.ObjectIds.Double)
    arg.ValueRank = -1
    arg.Description = ua.LocalizedText(description)
    return arg


async def add_identification(parent: Node, ns: Namespaces, nid: str,
                             fields: dict[str, str]) -> Node:
    ident = await parent.add_object(ua.NodeId(f"{nid}.Identification", ns.nodes),
                                    qn(ns.di, "Identification"))
    for key, value in fields.items():
        await ident.add_property(ua.NodeId(f"{nid}.Identification.{key}", ns.nodes),
                                 qn(ns.di, key), value, ua.VariantType.String)
    return ident


async def add_analog(parent: Node, ns_name: int, ns_id: int, nid: str, name: str, unit: str,
                     limits: tuple[float, float] | None) -> Node:
    var = await parent.add_variable(ua.NodeId(nid, ns_id), qn(ns_name, name), math.nan,
                                    ua.VariantType.Double)
    await var.add_property(ua.NodeId(f"{nid}.EngineeringUnits", ns_id),
                           qn(0, "EngineeringUnits"), eu_information(unit),
                           datatype=ua.NodeId(ua.ObjectIds.EUInformation))
    if limits is not None:
        await var.add_property(ua.NodeId(f"{nid}.EURange", ns_id), qn(0, "EURange"),
                               ua.Range(Low=limits[0], High=limits[1]),
                               datatype=ua.NodeId(ua.ObjectIds.Range))
    return var


async def build_model(server: Server, machine: Machine, source: str,
                      handler: MethodHandler, nodes_uri: str | None = None
                      ) -> tuple[Node, dict[str, AxisNodes]]:
    """Add the machine's nodes, their ids in ``nodes_uri`` (default: the machine's name as
    gateway id); methods call ``handler(axis, command, arguments)``."""
    nodes_uri = nodes_uri or application_uri(machine.name)
    ns = await register_namespaces(server, nodes_uri)
    m = machine.name
    objects = server.nodes.objects
    device_set = await objects.add_folder(ua.NodeId("DeviceSet", ns.nodes),
                                          qn(ns.di, "DeviceSet"))
    system = await device_set.add_object(ua.NodeId("MotionDeviceSystem", ns.nodes),
                                         qn(ns.robotics, "MotionDeviceSystem"))
    devices = await system.add_folder(ua.NodeId("MotionDevices", ns.nodes),
                                      qn(ns.robotics, "MotionDevices"))
    device = await devices.add_object(ua.NodeId(m, ns.nodes), qn(ns.servobus, m))
    await add_identification(device, ns, m, {
        "Manufacturer": MANUFACTURER, "Model": "servobus machine", "ProductInstanceUri":
        nodes_uri, "SoftwareRevision": __version__, "SerialNumber": source})
    axes_folder = await device.add_folder(ua.NodeId(f"{m}.Axes", ns.nodes),
                                          qn(ns.robotics, "Axes"))

    async def stop_all(parent: ua.NodeId, *args: ua.Variant) -> ua.StatusCode:
        if parent != device.nodeid:
            return ua.StatusCode(ua.StatusCodes.BadMethodInvalid)
        if args:
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        return await handler("", "stop_all", ())

    await device.add_method(ua.NodeId(f"{m}.StopAll", ns.nodes), qn(ns.servobus, "StopAll"),
                            stop_all, [], [])
    nodes: dict[str, AxisNodes] = {}
    for name, axis in machine.axes.items():
        nodes[name] = await _add_axis(axes_folder, ns, m, axis, handler)
    return device, nodes


async def _add_axis(folder: Node, ns: Namespaces, m: str, axis: MachineAxis,
                    handler: MethodHandler) -> AxisNodes:
    a = f"{m}.{axis.name}"
    obj = await folder.add_object(ua.NodeId(a, ns.nodes), qn(ns.servobus, axis.name))
    await add_identification(obj, ns, a, {
        "Manufacturer": family_title(axis), "Model": family_name(axis),
        "Protocol": str(axis.protocol), "DeviceAddress": f"{axis.url} id {axis.drive_id}"})
    params = await obj.add_object(ua.NodeId(f"{a}.ParameterSet", ns.nodes),
                                  qn(ns.di, "ParameterSet"))
    out = AxisNodes(axis, obj)
    out.variables["ActualPosition"] = await add_analog(
        params, ns.robotics, ns.nodes, f"{a}.ActualPosition", "ActualPosition", axis.unit,
        axis.limits)
    out.variables["ActualSpeed"] = await add_analog(
        params, ns.robotics, ns.nodes, f"{a}.ActualSpeed", "ActualSpeed", axis.speed_unit,
        None)
    for name, (vtype, initial) in STATE_VARIABLES.items():
        if name == "ActualCurrent":
            var = await add_analog(params, ns.servobus, ns.nodes, f"{a}.{name}", name, "A",
                                   None)
        else:
            var = await params.add_variable(ua.NodeId(f"{a}.{name}", ns.nodes),
                                            qn(ns.servobus, name), initial, vtype)
        out.variables[name] = var
    for name, vtype in HEALTH_VARIABLES.items():
        out.health[name] = await params.add_variable(
            ua.NodeId(f"{a}.{name}", ns.nodes), qn(ns.servobus, name),
            ua.get_default_value(vtype), vtype)
    for method, (command, arguments) in AXIS_METHODS.items():
        inputs = [method_argument(name, description) for name, description in arguments]
        await obj.add_method(ua.NodeId(f"{a}.{method}", ns.nodes), qn(ns.servobus, method),
                             _method(handler, axis.name, command, len(arguments), obj.nodeid),
                             inputs, [])
    return out


def _method(handler: MethodHandler, axis: str, command: str, count: int,
            owner: ua.NodeId) -> Callable[..., Awaitable[ua.StatusCode]]:
    """asyncua checks neither a call's object nor its arguments against the method's: a
    call on another object than ``owner`` (the method's axis) is BadMethodInvalid (Part 4,
    "the method id does not refer to a method for the specified object") and runs nothing;
    the arguments are checked here."""
    async def call(parent: ua.NodeId, *args: ua.Variant) -> ua.StatusCode:
        if parent != owner:
            return ua.StatusCode(ua.StatusCodes.BadMethodInvalid)
        if len(args) < count:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        if len(args) > count:
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        values = []
        for arg in args:
            value = getattr(arg, "Value", arg)
            if not isinstance(value, float | int) or isinstance(value, bool):
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            values.append(float(value))
        return await handler(axis, command, tuple(values))
    return call
