"""The OPC UA address space of one machine: OPC 40010-1 (Robotics) and OPC 10000-100 (DI)
objects, typed from the official NodeSets.

Decision (issue 36, docs/gateway.md "Information model"; it reverses the earlier one,
"browse names only, no NodeSets"): the DI, IA and Robotics NodeSets are imported at start
(servobus.gateway.opcua_nodesets), so a client that looks for types finds them; each object
is added with its TypeDefinition and this module adds the type's mandatory members itself
(servobus.gateway.opcua_nodes says why not asyncua's instantiation)::

    Objects
      DeviceSet (DI i=5001)
        MotionDeviceSystem            MotionDeviceSystemType
          MotionDevices
            <machine>                 MotionDeviceType: Manufacturer, Model, ProductCode,
                                      SerialNumber, MotionDeviceCategory, ParameterSet
                                      (SpeedOverride), Identification, StopAll()
              Axes
                <axis>                AxisType: MotionProfile, Identification, Alarm
                                      (servobus.gateway.opcua_alarms), the methods
                  ParameterSet        ActualPosition, ActualSpeed (Robotics), ActualCurrent
                                      (AnalogUnitType: EngineeringUnits, EURange);
                                      Enabled, Moving, InPosition, AlarmCode, AlarmText
                                      (readings: Bad while they cannot be read); Online,
                                      LastError, PowerLost, PowerLostReason, Interrupted
                                      (HEALTH_VARIABLES: the link's health, always Good)
              PowerTrains
                <axis>                PowerTrainType, Moves the axis
                  Motor               MotorType, IsDrivenBy the axis's controller
          Controllers
            <axis>                    ControllerType: the axis's drive; Controls the device
          SafetyStates
            <machine>                 SafetyStateType (EmergencyStop, ProtectiveStop: Bad,
                                      the gateway sees no safety circuit)

Node ids are strings in the gateway's own namespace, ``urn:servobus:gateway:<gateway id>``:
the machine ``<machine>``, an axis ``<machine>.<axis>``, any member its parent's id, a dot
and its browse name; so they stay the same from one start to the next and an aggregating
server keeps the nodes of many gateways apart. servobus's own browse names and types live
in ``urn:servobus:gateway``, the same in every gateway (servobus.gateway.identity). A link
going down or coming back is an event of LinkEventType emitted by the machine object (one
per link, not per axis). A method runs only when called on its own object (its axis, or
the machine for StopAll); on any other object it answers BadMethodInvalid and nothing runs.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from asyncua import Node, Server, ua

from servobus import __version__
from servobus.gateway.identity import TYPES_URI, application_uri
from servobus.gateway.opcua_nodes import (
    add_analog,
    add_folder,
    add_object,
    add_property,
    add_reference,
    add_variable,
)
from servobus.gateway.opcua_nodesets import DI_URI, ROBOTICS_URI, NodeSetIds, import_nodesets
from servobus.gateway.source import Machine, MachineAxis, family_name, family_title

SERVOBUS_URI = TYPES_URI  # browse names and types; node ids: the gateway's own namespace
MANUFACTURER = "servobus"
BASE_OBJECT = ua.NodeId(ua.ObjectIds.BaseObjectType)
BASE_VARIABLE = ua.NodeId(ua.ObjectIds.BaseDataVariableType)
#: Robotics data types and object types beyond NodeSetIds (official ids).
MOTION_DEVICE_CATEGORY = 18193
AXIS_MOTION_PROFILE = 3008
OPERATIONAL_MODE = 3006
USER_TYPE = 18175
FUNCTIONAL_GROUP = 1005  # DI

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
    ident = await add_object(parent, ua.NodeId(f"{nid}.Identification", ns.nodes),
                             qn(ns.di, "Identification"), ua.NodeId(FUNCTIONAL_GROUP, ns.di))
    for key, value in fields.items():
        await ident.add_property(ua.NodeId(f"{nid}.Identification.{key}", ns.nodes),
                                 qn(ns.di, key), value, ua.VariantType.String)
    return ident


#: AxisMotionProfileEnumeration (OPC 40010-1): OTHER 0, ROTARY 1, ROTARY_ENDLESS 2,
#: LINEAR 3, LINEAR_ENDLESS 4. An axis in ``counts`` is OTHER.
ROTARY_UNITS = {"deg", "rad", "rev"}
LINEAR_UNITS = {"mm", "m", "um", "µm", "in"}
#: MotionDeviceCategoryEnumeration: OTHER (a machine of servo axes is none of the robot
#: kinematics the enumeration names).
CATEGORY_OTHER = 0
#: SafetyStateType's EmergencyStop and ProtectiveStop: the gateway sees no safety circuit
#: (docs/safety.md), so they read Bad, never a guess.
UNKNOWN_SAFETY = ua.StatusCodes.BadNotSupported


def motion_profile(unit: str, continuous: bool) -> int:
    if unit in ROTARY_UNITS:
        return 2 if continuous else 1
    if unit in LINEAR_UNITS:
        return 4 if continuous else 3
    return 0


def _text(value: str) -> ua.Variant:
    return ua.Variant(ua.LocalizedText(value), ua.VariantType.LocalizedText)


def _string(value: str) -> ua.Variant:
    return ua.Variant(value, ua.VariantType.String)


async def _nameplate(node: Node, ns: Namespaces, manufacturer: str, model: str,
                     product_code: str, serial: str) -> None:
    """DI's mandatory Manufacturer, Model (LocalizedText), ProductCode, SerialNumber."""
    await add_property(node, qn(ns.di, "Manufacturer"), _text(manufacturer))
    await add_property(node, qn(ns.di, "Model"), _text(model))
    await add_property(node, qn(ns.di, "ProductCode"), _string(product_code))
    await add_property(node, qn(ns.di, "SerialNumber"), _string(serial))


def _rob(ns: Namespaces, ident: int) -> ua.NodeId:
    return ua.NodeId(ident, ns.robotics)


async def build_model(server: Server, machine: Machine, source: str,
                      handler: MethodHandler, nodes_uri: str | None = None,
                      sampling_ms: float = 0.0) -> tuple[Node, dict[str, AxisNodes]]:
    """Import the NodeSets and add the machine's typed nodes, their ids in ``nodes_uri``
    (default: the machine's name as gateway id); methods call ``handler(axis, command,
    arguments)``; ``sampling_ms`` is the readings' MinimumSamplingInterval."""
    nodes_uri = nodes_uri or application_uri(machine.name)
    await server.register_namespace(nodes_uri)
    await import_nodesets(server)
    ns = await register_namespaces(server, nodes_uri)
    m = machine.name
    t = NodeSetIds
    device_set = server.get_node(ua.NodeId(t.DEVICE_SET, ns.di))
    system = await add_object(device_set, ua.NodeId("MotionDeviceSystem", ns.nodes),
                              qn(ns.robotics, "MotionDeviceSystem"),
                              _rob(ns, t.MOTION_DEVICE_SYSTEM_TYPE))
    devices = await add_folder(system, ua.NodeId("MotionDevices", ns.nodes),
                               qn(ns.robotics, "MotionDevices"))
    controllers = await add_folder(system, ua.NodeId("Controllers", ns.nodes),
                                   qn(ns.robotics, "Controllers"))
    safety = await add_folder(system, ua.NodeId("SafetyStates", ns.nodes),
                              qn(ns.robotics, "SafetyStates"))
    device = await add_object(devices, ua.NodeId(m, ns.nodes), qn(ns.servobus, m),
                              _rob(ns, t.MOTION_DEVICE_TYPE))
    await _nameplate(device, ns, MANUFACTURER, "servobus machine", "servobus-machine", source)
    await add_property(device, qn(ns.robotics, "MotionDeviceCategory"),
                       ua.Variant(CATEGORY_OTHER, ua.VariantType.Int32),
                       _rob(ns, MOTION_DEVICE_CATEGORY))
    params = await add_object(device, ua.NodeId(f"{m}.ParameterSet", ns.nodes),
                              qn(ns.di, "ParameterSet"), BASE_OBJECT)
    await add_variable(params, ua.NodeId(f"{m}.ParameterSet.SpeedOverride", ns.nodes),
                       qn(ns.robotics, "SpeedOverride"),
                       ua.Variant(100.0, ua.VariantType.Double), ua.NodeId(ua.ObjectIds.Double),
                       BASE_VARIABLE)  # no override: every move runs at its own speed
    await add_identification(device, ns, m, {
        "Manufacturer": MANUFACTURER, "Model": "servobus machine", "ProductInstanceUri":
        nodes_uri, "SoftwareRevision": __version__, "SerialNumber": source})
    axes_folder = await add_folder(device, ua.NodeId(f"{m}.Axes", ns.nodes),
                                   qn(ns.robotics, "Axes"))
    trains = await add_folder(device, ua.NodeId(f"{m}.PowerTrains", ns.nodes),
                              qn(ns.robotics, "PowerTrains"))
    await _safety_state(safety, ns, m)

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
        axis_nodes = await _add_axis(axes_folder, ns, m, axis, handler, sampling_ms)
        drive = await _add_controller(controllers, ns, m, axis, device)
        await _add_power_train(trains, ns, m, axis, axis_nodes.node, drive, sampling_ms)
        nodes[name] = axis_nodes
    return device, nodes


async def _safety_state(folder: Node, ns: Namespaces, m: str) -> None:
    state = await add_object(folder, ua.NodeId(f"SafetyStates.{m}", ns.nodes),
                             qn(ns.servobus, m), _rob(ns, NodeSetIds.SAFETY_STATE_TYPE))
    params = await add_object(state, ua.NodeId(f"SafetyStates.{m}.ParameterSet", ns.nodes),
                              qn(ns.di, "ParameterSet"), BASE_OBJECT)
    await add_variable(params, ua.NodeId(f"SafetyStates.{m}.OperationalMode", ns.nodes),
                       qn(ns.robotics, "OperationalMode"),
                       ua.Variant(0, ua.VariantType.Int32),  # OTHER: servobus has no modes
                       _rob(ns, OPERATIONAL_MODE), BASE_VARIABLE)
    for name in ("EmergencyStop", "ProtectiveStop"):
        var = await add_variable(params, ua.NodeId(f"SafetyStates.{m}.{name}", ns.nodes),
                                 qn(ns.robotics, name), ua.Variant(False),
                                 ua.NodeId(ua.ObjectIds.Boolean), BASE_VARIABLE)
        await var.write_value(ua.DataValue(StatusCode=ua.StatusCode(UNKNOWN_SAFETY)))


async def _add_controller(folder: Node, ns: Namespaces, m: str, axis: MachineAxis,
                          device: Node) -> Node:
    """The axis's drive as a ControllerType: it Controls the MotionDevice."""
    c = f"{m}.Controllers.{axis.name}"
    drive = await add_object(folder, ua.NodeId(c, ns.nodes), qn(ns.servobus, axis.name),
                             _rob(ns, NodeSetIds.CONTROLLER_TYPE))
    await _nameplate(drive, ns, family_title(axis), family_name(axis), family_name(axis),
                     f"{axis.url} id {axis.drive_id}")
    user = await add_object(drive, ua.NodeId(f"{c}.CurrentUser", ns.nodes),
                            qn(ns.robotics, "CurrentUser"), _rob(ns, USER_TYPE))
    await add_property(user, qn(ns.robotics, "Level"), _string(""))  # nobody logs on a drive
    await add_folder(drive, ua.NodeId(f"{c}.Software", ns.nodes), qn(ns.robotics, "Software"))
    await add_folder(drive, ua.NodeId(f"{c}.TaskControls", ns.nodes),
                     qn(ns.robotics, "TaskControls"))
    await add_reference(drive, device, _rob(ns, NodeSetIds.CONTROLS))
    return drive


async def _add_power_train(folder: Node, ns: Namespaces, m: str, axis: MachineAxis,
                           axis_node: Node, drive: Node, sampling_ms: float) -> None:
    """PowerTrain (Moves the axis) with its Motor, which IsDrivenBy the drive."""
    p = f"{m}.PowerTrains.{axis.name}"
    train = await add_object(folder, ua.NodeId(p, ns.nodes), qn(ns.servobus, axis.name),
                             _rob(ns, NodeSetIds.POWER_TRAIN_TYPE))
    motor = await add_object(train, ua.NodeId(f"{p}.Motor", ns.nodes),
                             qn(ns.servobus, "Motor"), _rob(ns, NodeSetIds.MOTOR_TYPE))
    await _nameplate(motor, ns, family_title(axis), family_name(axis), family_name(axis), "")
    params = await add_object(motor, ua.NodeId(f"{p}.Motor.ParameterSet", ns.nodes),
                              qn(ns.di, "ParameterSet"), BASE_OBJECT)
    temperature = await add_analog(params, qn(ns.robotics, "MotorTemperature"), "°C", None,
                                   sampling_ms)
    await temperature.write_value(ua.DataValue(  # no family reports it (docs/gateway.md)
        StatusCode=ua.StatusCode(ua.StatusCodes.BadNotSupported)))
    await add_reference(train, axis_node, _rob(ns, NodeSetIds.MOVES))
    await add_reference(axis_node, train, _rob(ns, NodeSetIds.REQUIRES))
    await add_reference(motor, drive, _rob(ns, NodeSetIds.IS_DRIVEN_BY))


async def _add_axis(folder: Node, ns: Namespaces, m: str, axis: MachineAxis,
                    handler: MethodHandler, sampling_ms: float) -> AxisNodes:
    a = f"{m}.{axis.name}"
    obj = await add_object(folder, ua.NodeId(a, ns.nodes), qn(ns.servobus, axis.name),
                           _rob(ns, NodeSetIds.AXIS_TYPE))
    await add_property(obj, qn(ns.robotics, "MotionProfile"),
                       ua.Variant(motion_profile(axis.unit, axis.continuous),
                                  ua.VariantType.Int32),
                       _rob(ns, AXIS_MOTION_PROFILE))
    await add_identification(obj, ns, a, {
        "Manufacturer": family_title(axis), "Model": family_name(axis),
        "Protocol": str(axis.protocol), "DeviceAddress": f"{axis.url} id {axis.drive_id}"})
    params = await add_object(obj, ua.NodeId(f"{a}.ParameterSet", ns.nodes),
                              qn(ns.di, "ParameterSet"), BASE_OBJECT)
    out = AxisNodes(axis, obj)
    out.variables["ActualPosition"] = await add_analog(
        params, qn(ns.robotics, "ActualPosition"), axis.unit, axis.limits, sampling_ms)
    out.variables["ActualSpeed"] = await add_analog(
        params, qn(ns.robotics, "ActualSpeed"), axis.speed_unit, None, sampling_ms)
    for name, (vtype, initial) in STATE_VARIABLES.items():
        if name == "ActualCurrent":
            var = await add_analog(params, qn(ns.servobus, name), "A", None, sampling_ms)
        else:
            var = await add_variable(params, ua.NodeId(f"{a}.ParameterSet.{name}", ns.nodes),
                                     qn(ns.servobus, name), ua.Variant(initial, vtype),
                                     ua.NodeId(vtype.value), BASE_VARIABLE,
                                     sampling_ms=sampling_ms)
        out.variables[name] = var
    for name, vtype in HEALTH_VARIABLES.items():
        out.health[name] = await add_variable(
            params, ua.NodeId(f"{a}.ParameterSet.{name}", ns.nodes), qn(ns.servobus, name),
            ua.Variant(ua.get_default_value(vtype), vtype), ua.NodeId(vtype.value),
            BASE_VARIABLE, sampling_ms=sampling_ms)
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
