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

Node ids are strings in the servobus namespace (``<machine>.<axis>.ActualPosition``), so
they stay the same from one start to the next. Alarms are events of AxisAlarmEventType
(servobus namespace, a BaseEventType) emitted by the axis object; a link going down or
coming back is an event of LinkEventType emitted by the machine object (one per link, not
per axis).
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from asyncua import Node, Server, ua

from servobus import __version__
from servobus.gateway.source import Machine, MachineAxis, family_name, family_title
from servobus.gateway.units import eu_information

DI_URI = "http://opcfoundation.org/UA/DI/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
SERVOBUS_URI = "urn:servobus:gateway"
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
    servobus: int


def qn(ns: int, name: str) -> ua.QualifiedName:
    return ua.QualifiedName(name, ns)


async def register_namespaces(server: Server) -> Namespaces:
    return Namespaces(await server.register_namespace(DI_URI),
                      await server.register_namespace(ROBOTICS_URI),
                      await server.register_namespace(SERVOBUS_URI))


def method_argument(name: str, description: str) -> ua.Argument:
    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(ua.ObjectIds.Double)
    arg.ValueRank = -1
    arg.Description = ua.LocalizedText(description)
    return arg


async def add_identification(parent: Node, ns: Namespaces, nid: str,
                             fields: dict[str, str]) -> Node:
    ident = await parent.add_object(ua.NodeId(f"{nid}.Identification", ns.servobus),
                                    qn(ns.di, "Identification"))
    for key, value in fields.items():
        await ident.add_property(ua.NodeId(f"{nid}.Identification.{key}", ns.servobus),
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
                      handler: MethodHandler) -> tuple[Node, dict[str, AxisNodes]]:
    """Add the machine's nodes; methods call ``handler(axis, command, arguments)``."""
    ns = await register_namespaces(server)
    m = machine.name
    objects = server.nodes.objects
    device_set = await objects.add_folder(ua.NodeId("DeviceSet", ns.servobus),
                                          qn(ns.di, "DeviceSet"))
    system = await device_set.add_object(ua.NodeId("MotionDeviceSystem", ns.servobus),
                                         qn(ns.robotics, "MotionDeviceSystem"))
    devices = await system.add_folder(ua.NodeId("MotionDevices", ns.servobus),
                                      qn(ns.robotics, "MotionDevices"))
    device = await devices.add_object(ua.NodeId(m, ns.servobus), qn(ns.servobus, m))
    await add_identification(device, ns, m, {
        "Manufacturer": MANUFACTURER, "Model": "servobus machine", "ProductInstanceUri":
        f"{SERVOBUS_URI}:{m}", "SoftwareRevision": __version__, "SerialNumber": source})
    axes_folder = await device.add_folder(ua.NodeId(f"{m}.Axes", ns.servobus),
                                          qn(ns.robotics, "Axes"))

    async def stop_all(parent: ua.NodeId) -> ua.StatusCode:
        return await handler("", "stop_all", ())

    await device.add_method(ua.NodeId(f"{m}.StopAll", ns.servobus), qn(ns.servobus, "StopAll"),
                            stop_all, [], [])
    nodes: dict[str, AxisNodes] = {}
    for name, axis in machine.axes.items():
        nodes[name] = await _add_axis(axes_folder, ns, m, axis, handler)
    return device, nodes


async def _add_axis(folder: Node, ns: Namespaces, m: str, axis: MachineAxis,
                    handler: MethodHandler) -> AxisNodes:
    a = f"{m}.{axis.name}"
    obj = await folder.add_object(ua.NodeId(a, ns.servobus), qn(ns.servobus, axis.name))
    await add_identification(obj, ns, a, {
        "Manufacturer": family_title(axis), "Model": family_name(axis),
        "Protocol": str(axis.protocol), "DeviceAddress": f"{axis.url} id {axis.drive_id}"})
    params = await obj.add_object(ua.NodeId(f"{a}.ParameterSet", ns.servobus),
                                  qn(ns.di, "ParameterSet"))
    out = AxisNodes(axis, obj)
    out.variables["ActualPosition"] = await add_analog(
        params, ns.robotics, ns.servobus, f"{a}.ActualPosition", "ActualPosition", axis.unit,
        axis.limits)
    out.variables["ActualSpeed"] = await add_analog(
        params, ns.robotics, ns.servobus, f"{a}.ActualSpeed", "ActualSpeed", axis.speed_unit,
        None)
    for name, (vtype, initial) in STATE_VARIABLES.items():
        if name == "ActualCurrent":
            var = await add_analog(params, ns.servobus, ns.servobus, f"{a}.{name}", name, "A",
                                   None)
        else:
            var = await params.add_variable(ua.NodeId(f"{a}.{name}", ns.servobus),
                                            qn(ns.servobus, name), initial, vtype)
        out.variables[name] = var
    for name, vtype in HEALTH_VARIABLES.items():
        out.health[name] = await params.add_variable(
            ua.NodeId(f"{a}.{name}", ns.servobus), qn(ns.servobus, name),
            ua.get_default_value(vtype), vtype)
    for method, (command, arguments) in AXIS_METHODS.items():
        inputs = [method_argument(name, description) for name, description in arguments]
        await obj.add_method(ua.NodeId(f"{a}.{method}", ns.servobus), qn(ns.servobus, method),
                             _method(handler, axis.name, command, len(arguments)), inputs, [])
    return out


def _method(handler: MethodHandler, axis: str, command: str,
            count: int) -> Callable[..., Awaitable[ua.StatusCode]]:
    """asyncua does not check a call's arguments against the method's: check them here."""
    async def call(parent: ua.NodeId, *args: ua.Variant) -> ua.StatusCode:
        if len(args) < count:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        if len(args) > count:
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        values = []
        for arg in args:
            if not isinstance(arg.Value, float | int) or isinstance(arg.Value, bool):
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            values.append(float(arg.Value))
        return await handler(axis, command, tuple(values))
    return call
