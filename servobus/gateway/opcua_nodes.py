"""Typed nodes without asyncua's instantiation.

asyncua's ``add_object(..., objecttype)`` copies every member of the type that has a
modelling rule, MandatoryPlaceholders included: a MotionDeviceSystem would get a whole
MotionDevice named ``<MotionDeviceIdentifier>``. The model therefore adds each node with
its TypeDefinition and adds the type's mandatory members itself (servobus.gateway
.opcua_model), which is also faster.
"""

from __future__ import annotations

import math

from asyncua import Node, ua

from servobus.gateway.units import eu_information

HAS_COMPONENT = ua.ObjectIds.HasComponent
HAS_PROPERTY = ua.ObjectIds.HasProperty
ANALOG_UNIT_TYPE = ua.NodeId(ua.ObjectIds.AnalogUnitType)
UNBOUNDED = (-math.inf, math.inf)


async def add_object(parent: Node, nodeid: ua.NodeId, bname: ua.QualifiedName,
                     typedef: ua.NodeId, ref: int = HAS_COMPONENT) -> Node:
    item = ua.AddNodesItem()
    item.RequestedNewNodeId = nodeid
    item.BrowseName = bname
    item.NodeClass = ua.NodeClass.Object
    item.ParentNodeId = parent.nodeid
    item.ReferenceTypeId = ua.NodeId(ref)
    item.TypeDefinition = typedef
    attrs = ua.ObjectAttributes()
    attrs.DisplayName = ua.LocalizedText(bname.Name)
    attrs.EventNotifier = 0
    item.NodeAttributes = attrs
    result = (await parent.session.add_nodes([item]))[0]
    result.StatusCode.check()
    return Node(parent.session, result.AddedNodeId)


async def add_folder(parent: Node, nodeid: ua.NodeId, bname: ua.QualifiedName) -> Node:
    return await add_object(parent, nodeid, bname, ua.NodeId(ua.ObjectIds.FolderType))


async def add_variable(parent: Node, nodeid: ua.NodeId, bname: ua.QualifiedName,
                       value: ua.Variant, datatype: ua.NodeId, typedef: ua.NodeId,
                       ref: int = HAS_COMPONENT, sampling_ms: float = 0.0) -> Node:
    item = ua.AddNodesItem()
    item.RequestedNewNodeId = nodeid
    item.BrowseName = bname
    item.NodeClass = ua.NodeClass.Variable
    item.ParentNodeId = parent.nodeid
    item.ReferenceTypeId = ua.NodeId(ref)
    item.TypeDefinition = typedef
    attrs = ua.VariableAttributes()
    attrs.DisplayName = ua.LocalizedText(bname.Name)
    attrs.Value = value
    attrs.DataType = datatype
    attrs.ValueRank = ua.ValueRank.Scalar
    attrs.MinimumSamplingInterval = sampling_ms
    item.NodeAttributes = attrs
    result = (await parent.session.add_nodes([item]))[0]
    result.StatusCode.check()
    return Node(parent.session, result.AddedNodeId)


async def add_property(parent: Node, name: ua.QualifiedName, value: ua.Variant,
                       datatype: ua.NodeId | None = None) -> Node:
    """A property whose id is its parent's id and its name (``x.Model``)."""
    nid = ua.NodeId(f"{parent.nodeid.Identifier}.{name.Name}", parent.nodeid.NamespaceIndex)
    dtype = datatype if datatype is not None else ua.NodeId(value.VariantType.value)
    return await add_variable(parent, nid, name, value, dtype,
                              ua.NodeId(ua.ObjectIds.PropertyType), HAS_PROPERTY)


async def add_analog(parent: Node, name: ua.QualifiedName, unit: str,
                     eu_range: tuple[float, float] | None, sampling_ms: float) -> Node:
    """An AnalogUnitType Double (NaN until written) with its EngineeringUnits and
    EURange (unbounded, -inf..inf, where the gateway knows no bound)."""
    nid = ua.NodeId(f"{parent.nodeid.Identifier}.{name.Name}", parent.nodeid.NamespaceIndex)
    var = await add_variable(parent, nid, name, ua.Variant(math.nan, ua.VariantType.Double),
                             ua.NodeId(ua.ObjectIds.Double), ANALOG_UNIT_TYPE,
                             sampling_ms=sampling_ms)
    await add_property(var, ua.QualifiedName("EngineeringUnits", 0),
                       ua.Variant(eu_information(unit), ua.VariantType.ExtensionObject),
                       ua.NodeId(ua.ObjectIds.EUInformation))
    low, high = eu_range if eu_range is not None else UNBOUNDED
    await add_property(var, ua.QualifiedName("EURange", 0),
                       ua.Variant(ua.Range(Low=low, High=high), ua.VariantType.ExtensionObject),
                       ua.NodeId(ua.ObjectIds.Range))
    return var


async def add_reference(source: Node, target: Node, ref: ua.NodeId) -> None:
    await source.add_reference(target.nodeid, ref, forward=True, bidirectional=True)
