"""The cell's devices as the OPC UA companion specifications type them: DI and OPC 40010.

The gateway loads the OPC Foundation's NodeSets shipped in ``nodesets/`` — DI (OPC
10000-100), IA (OPC 10000-200, which Robotics requires) and Robotics (OPC 40010-1) — with
asyncua's ``Server.import_xml``, and puts one typed object per live service into DI's
``Objects/DeviceSet`` (where DI and OPC 40010 say devices are)::

    DeviceSet/
      <ROBOT>                          MotionDeviceSystemType (40010)
        MotionDevices/<ROBOT>          MotionDeviceType: Manufacturer, Model, ProductCode,
                                       SerialNumber, MotionDeviceCategory,
                                       ParameterSet/SpeedOverride
          Axes/Axis1 … AxisN           AxisType: MotionProfile, ParameterSet/ActualPosition,
                                       ActualSpeed (AnalogUnitType, °, °/s)
          PowerTrains/PowerTrain1 … N  PowerTrainType (Moves AxisK), Motor1 (MotorType)
          FlangePose                   Double[6] (plugcell: x y z mm, a b c ° ZYZ)
        Controllers/Controller         ControllerType: identification, CurrentUser,
                                       Software/RobotService, TaskControls/Program
        SafetyStates/Safety            SafetyStateType
      <SERVICE>                        ServiceDeviceType (this namespace; a DI DeviceType):
                                       Manufacturer, Model, SerialNumber, revisions …

Types are instantiated with asyncua (``add_object(objecttype=…)``, mandatory children
only); the string NodeIds asyncua gives a type's children are the parent's joined with
``.`` and the browse name (``DeviceSet.ROBOT.MotionDevices``), and so are the ones added
here.  asyncua instantiates a type's *placeholders* (``<AxisIdentifier>`` …) as if they
were children; they are removed (:func:`add_instance`) and real instances added in their
place.  Values this gateway does not know (a robot's safety state, its speed override)
are Null with the status ``BadNotSupported``, so that a client sees "not provided", not
a made-up value.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from importlib.resources import files
from typing import Any

from asyncua import Node, Server, ua
from asyncua.common.ua_utils import get_node_subtypes

log = logging.getLogger("plugcell.devices.opcua")

DI_URI = "http://opcfoundation.org/UA/DI/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
#: Loaded in this order (each needs the ones before).
NODESETS = ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.IA.NodeSet2.xml", "Opc.Ua.Robotics.NodeSet2.xml")

#: UNECE units (OPC 10000-8 §5.6.3: UnitId from the common code).
_UNECE = "http://www.opcfoundation.org/UA/units/un/cefact"


def _unit(code: str, symbol: str, text: str) -> ua.EUInformation:
    unit_id = 0
    for char in code:
        unit_id = (unit_id << 8) | ord(char)
    return ua.EUInformation(NamespaceUri=_UNECE, UnitId=unit_id,
                            DisplayName=ua.LocalizedText(symbol),
                            Description=ua.LocalizedText(text))


DEGREE = _unit("DD", "°", "degree [unit of angle]")
DEGREE_PER_SECOND = _unit("E96", "°/s", "degree per second")

#: The NodeId number of OPC 40010's reference type Moves (PowerTrain → Axis, hierarchical).
MOVES = 18178

#: MotionDeviceCategoryEnumeration (OPC 40010-1 §10.1) and AxisMotionProfileEnumeration.
ARTICULATED_ROBOT, ROTARY = 1, 1


def nodeset_xml(name: str) -> str:
    """A shipped NodeSet without its ``DesignToolOnly`` nodes (design-time helpers that
    have no parent and that asyncua's importer cannot place)."""
    root = ET.fromstring(files("plugcell.devices.opcua").joinpath("nodesets", name)
                         .read_bytes())
    for element in list(root):
        if element.get("DesignToolOnly") == "true":
            root.remove(element)
    return ET.tostring(root, encoding="unicode")


@dataclass
class Models:
    """The loaded companion models of one server: namespaces and the types used here."""

    server: Server
    idx: int
    """The cell's namespace."""
    di: int
    robotics: int
    device_set: Node
    types: dict[str, ua.NodeId] = field(default_factory=dict)
    """Type NodeIds by name (``MotionDeviceType``, ``ServiceDeviceType`` …)."""
    moves: ua.NodeId = field(default_factory=ua.NodeId)
    """The 40010 reference type PowerTrain → Axis."""


async def load_models(server: Server, idx: int) -> Models:
    """Import DI, IA and Robotics into ``server``; add ``ServiceDeviceType`` (DeviceType)
    in the cell's namespace ``idx``."""
    asyncua_log = logging.getLogger("asyncua")
    level = asyncua_log.level
    asyncua_log.setLevel(logging.ERROR)  # the importer warns of every structure it skips
    try:
        for name in NODESETS:
            await server.import_xml(xmlstring=nodeset_xml(name))
    finally:
        asyncua_log.setLevel(level)
    di = await server.get_namespace_index(DI_URI)
    robotics = await server.get_namespace_index(ROBOTICS_URI)
    wanted = {(di, "DeviceType"), (di, "SoftwareType"), (robotics, "MotionDeviceSystemType"),
              (robotics, "MotionDeviceType"), (robotics, "AxisType"),
              (robotics, "PowerTrainType"), (robotics, "MotorType"),
              (robotics, "ControllerType"), (robotics, "TaskControlType"),
              (robotics, "SafetyStateType")}
    types: dict[str, ua.NodeId] = {}
    for node in await get_node_subtypes(server.nodes.base_object_type):
        name = await node.read_browse_name()
        if (name.NamespaceIndex, name.Name) in wanted:
            types[name.Name] = node.nodeid
    missing = {n for _, n in wanted} - set(types)
    if missing:
        raise RuntimeError(f"the companion NodeSets lack the types {sorted(missing)}")
    device_type = server.get_node(types["DeviceType"])
    service_type = await device_type.add_object_type(
        ua.NodeId("ServiceDeviceType", idx), ua.QualifiedName("ServiceDeviceType", idx))
    await service_type.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
        ua.LocalizedText("a plugcell service's device (DI DeviceType); its commands are the "
                         "methods of Objects/Cell/<service>"), ua.VariantType.LocalizedText)))
    types["ServiceDeviceType"] = service_type.nodeid
    moves = ua.NodeId(MOVES, robotics)
    if (await server.get_node(moves).read_browse_name()).Name != "Moves":
        raise RuntimeError(f"the Robotics NodeSet has no reference type Moves at {moves}")
    device_set = await server.nodes.objects.get_child(f"{di}:DeviceSet")
    return Models(server, idx, di, robotics, device_set, types, moves)


async def add_instance(models: Models, parent: Node, name: str, type_name: str,
                       ns: int | None = None) -> Node:
    """An object of type ``type_name`` below ``parent`` with its mandatory children (the
    type's placeholders removed); NodeId ``<parent id>.<name>`` (``DeviceSet.<name>`` at
    the top)."""
    ns = models.idx if ns is None else ns
    pid = parent.nodeid
    ident = (f"{pid.Identifier}.{name}" if pid.NamespaceIndex == models.idx
             and pid.NodeIdType is ua.NodeIdType.String else f"DeviceSet.{name}")
    node = await parent.add_object(ua.NodeId(ident, models.idx), ua.QualifiedName(name, ns),
                                   objecttype=models.types[type_name],
                                   instantiate_optional=False)
    await _drop_placeholders(node)
    return node


async def _drop_placeholders(node: Node) -> None:
    for child in await node.get_children(refs=ua.ObjectIds.HierarchicalReferences):
        if child.nodeid.NamespaceIndex == 0:
            continue  # a type's reference to a shared node (never a placeholder)
        name = (await child.read_browse_name()).Name
        if name.startswith("<") and name.endswith(">"):
            await child.delete(recursive=True)
        else:
            await _drop_placeholders(child)


async def child(node: Node, *path: str) -> Node:
    """A descendant by browse names (``"2:ParameterSet"``, …)."""
    return await node.get_child(list(path))


async def set_value(node: Node, value: Any, vtype: ua.VariantType) -> None:
    await node.write_value(ua.DataValue(ua.Variant(value, vtype)))


async def not_supported(node: Node) -> None:
    """Null, ``BadNotSupported``: the gateway does not know this value."""
    await node.write_value(ua.DataValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadNotSupported)))


async def identify(models: Models, node: Node, manufacturer: str, model: str,
                   serial: str = "", product_code: str = "") -> None:
    """DI identification (Manufacturer, Model: LocalizedText; SerialNumber, ProductCode:
    String) of a component or device, where the type has them."""
    di = models.di
    for key, value in (("Manufacturer", manufacturer), ("Model", model)):
        try:
            var = await node.get_child(f"{di}:{key}")
        except ua.UaStatusCodeError:
            continue
        await set_value(var, ua.LocalizedText(value), ua.VariantType.LocalizedText)
    for key, value in (("SerialNumber", serial), ("ProductCode", product_code)):
        try:
            var = await node.get_child(f"{di}:{key}")
        except ua.UaStatusCodeError:
            continue
        await set_value(var, value, ua.VariantType.String)


async def add_service_device(models: Models, name: str, vendor: str, kind: str,
                             info: str) -> Node:
    """``DeviceSet/<name>``, a ``ServiceDeviceType`` (a DI device) of a plugcell service."""
    node = await add_instance(models, models.device_set, name, "ServiceDeviceType")
    await identify(models, node, vendor, kind)
    await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
        ua.LocalizedText(info), ua.VariantType.LocalizedText)))
    return node
