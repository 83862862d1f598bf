"""The gateway's address space: one object per service, one Method per command.

Layout (namespace ``urn:plugcell:cell:<cell>``, string NodeIds = browse paths)::

    Objects/Cell                                   FolderType
      <SERVICE>                                    BaseObjectType, one per live service
        Kind, Vendor, Info, Instance               String  (DeviceInfo, Table F-6)
        Manufacturer, Model                        String  (OPC 10000-100 DI names)
        DeviceHealth                               Int32   (DI DeviceHealthEnumeration:
                                                            0 NORMAL, 1 FAILURE)
        DeviceState, ConnectionState               String  (live: StateUpdate,
                                                            ConnectionUpdate)
        Partners                                   String[]
        <Command>(Option, Data) -> Data | Process  Method per catalogue command
        Processes/                                 FolderType
          <identifier>                             a MultipleData process
            Command, Sender, State, Reason         String
            Frames                                 UInt32
            Data                                   the command's output type/size
            Stop() -> Reason                       Method

A robot service also gets ``Axes/AxisN/ParameterSet/ActualPosition`` and
``FlangePose`` (OPC 40010 names; :mod:`plugcell.devices.opcua.robots`).  The nodes of a service
are made by :func:`add_service` and deleted, children and all, by
:meth:`ServiceNode.delete`.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from asyncua import Node, ua

from plugcell.devices.opcua.arguments import (
    data_argument,
    empty_variant,
    input_arguments,
    string_argument,
    value_rank,
)
from plugcell.framework.messages import Command, CommandTypes, Device, DeviceStates

MethodHandler = Callable[..., Awaitable[Any]]

#: DI DeviceHealthEnumeration values used here (OPC 10000-100 §5.5.4).
DEVICE_HEALTH_NORMAL, DEVICE_HEALTH_FAILURE = 0, 1


def node_id(idx: int, *path: str) -> ua.NodeId:
    """The string NodeId of a browse path below ``Cell`` (``Cell/CAMERA/SnapShot``)."""
    return ua.NodeId("/".join(("Cell", *path)), idx)


#: The last output argument of every method: why the call failed ("" when it did not).
REASON_ARGUMENT = string_argument(
    "Reason", "why the call failed (the service's reason, as in its journal); empty when it "
    "succeeded")


def output_argument(command: Command) -> list[ua.Argument]:
    """``Data`` for SingleData with output, ``Process`` (a NodeId) for MultipleData; then
    ``Reason`` (String) for every command."""
    if command.type is CommandTypes.MultipleData:
        arg = ua.Argument()
        arg.Name = "Process"
        arg.DataType = ua.NodeId(ua.ObjectIds.NodeId)
        arg.ValueRank = int(ua.ValueRank.Scalar)
        arg.Description = ua.LocalizedText(
            "the process object: subscribe to its Data, call its Stop"
        )
        return [arg, REASON_ARGUMENT]
    if command.gives_output:
        return [data_argument("Data", command.output_data_type, command.output_data_size),
                REASON_ARGUMENT]
    return [REASON_ARGUMENT]


@dataclass
class ServiceNode:
    """The nodes of one service and the variables the gateway keeps current."""

    name: str
    idx: int
    node: Node
    variables: dict[str, Node]
    processes: Node
    commands: dict[str, Command] = field(default_factory=dict)
    device: Node | None = None
    """Its typed object in DI's DeviceSet (:mod:`plugcell.devices.opcua.companion`)."""

    async def set(self, variable: str, value: Any, vtype: ua.VariantType) -> None:
        await self.variables[variable].write_value(ua.Variant(value, vtype))

    async def show_device(self, device: Device, partners: list[str]) -> None:
        """Write the live parts of the DeviceInfo (state, connection, partners)."""
        await self.set("DeviceState", device.state.value, ua.VariantType.String)
        await self.set("ConnectionState", device.connection.value, ua.VariantType.String)
        health = DEVICE_HEALTH_FAILURE if device.state is DeviceStates.Error else (
            DEVICE_HEALTH_NORMAL)
        await self.set("DeviceHealth", health, ua.VariantType.Int32)
        await self.set("Partners", partners, ua.VariantType.String)

    async def delete(self) -> None:
        await self.node.delete(recursive=True)


async def add_service(
    cell: Node,
    idx: int,
    device: Device,
    instance: str,
    partners: list[str],
    handler: Callable[[Command], MethodHandler],
) -> ServiceNode:
    """Create ``Cell/<SERVICE>`` with its DeviceInfo variables and one Method per command.

    ``handler(command)`` gives the method's callback (``async (parent, *variants)``).
    """
    name = device.name
    node = await cell.add_object(node_id(idx, name), ua.QualifiedName(name, idx))
    await node.write_attribute(
        ua.AttributeIds.Description,
        ua.DataValue(ua.Variant(ua.LocalizedText(device.info), ua.VariantType.LocalizedText)),
    )
    variables: dict[str, Node] = {}
    fixed = {
        "Kind": device.kind, "Vendor": device.vendor, "Info": device.info, "Instance": instance,
        "Manufacturer": device.vendor, "Model": device.kind,
    }
    for key, text in fixed.items():
        variables[key] = await node.add_property(
            node_id(idx, name, key), ua.QualifiedName(key, idx),
            ua.Variant(text, ua.VariantType.String),
        )
    live: dict[str, ua.Variant] = {
        "DeviceState": ua.Variant(device.state.value, ua.VariantType.String),
        "ConnectionState": ua.Variant(device.connection.value, ua.VariantType.String),
        "DeviceHealth": ua.Variant(DEVICE_HEALTH_NORMAL, ua.VariantType.Int32),
        "Partners": ua.Variant(partners, ua.VariantType.String),
    }
    for key, variant in live.items():
        variables[key] = await node.add_variable(
            node_id(idx, name, key), ua.QualifiedName(key, idx), variant
        )
    processes = await node.add_folder(
        node_id(idx, name, "Processes"), ua.QualifiedName("Processes", idx)
    )
    service = ServiceNode(name, idx, node, variables, processes)
    for command in device.commands:
        method = await node.add_method(
            node_id(idx, name, command.name),
            ua.QualifiedName(command.name, idx),
            handler(command),
            input_arguments(command),
            output_argument(command),
        )
        await method.write_attribute(
            ua.AttributeIds.Description,
            ua.DataValue(ua.Variant(
                ua.LocalizedText(f"{command.type.value}: {command.info}".rstrip(": ")),
                ua.VariantType.LocalizedText,
            )),
        )
        service.commands[command.name] = command
    await service.show_device(device, partners)
    return service


@dataclass
class ProcessNode:
    """The object of one MultipleData process (``Cell/<S>/Processes/<identifier>``)."""

    node: Node
    state: Node
    reason: Node
    frames: Node
    data: Node


async def add_process(
    service: ServiceNode,
    command: Command,
    sender: str,
    identifier: int,
    stop: MethodHandler,
) -> ProcessNode:
    """Create the process object with its variables and its ``Stop`` method."""
    idx, name, key = service.idx, service.name, str(identifier)

    def nid(*rest: str) -> ua.NodeId:
        return node_id(idx, name, "Processes", key, *rest)

    node = await service.processes.add_object(nid(), ua.QualifiedName(key, idx))
    for prop, text in (("Command", command.name), ("Sender", sender)):
        await node.add_property(nid(prop), ua.QualifiedName(prop, idx),
                                ua.Variant(text, ua.VariantType.String))
    state = await node.add_variable(nid("State"), ua.QualifiedName("State", idx),
                                    ua.Variant("Running", ua.VariantType.String))
    reason = await node.add_variable(nid("Reason"), ua.QualifiedName("Reason", idx),
                                     ua.Variant("", ua.VariantType.String))
    frames = await node.add_variable(nid("Frames"), ua.QualifiedName("Frames", idx),
                                     ua.Variant(0, ua.VariantType.UInt32))
    data = await node.add_variable(
        nid("Data"), ua.QualifiedName("Data", idx),
        empty_variant(command.output_data_type, command.output_data_size),
    )
    rank, dims = value_rank(command.output_data_size)
    await data.write_attribute(ua.AttributeIds.ValueRank,
                               ua.DataValue(ua.Variant(rank, ua.VariantType.Int32)))
    if dims:
        await data.write_attribute(ua.AttributeIds.ArrayDimensions,
                                   ua.DataValue(ua.Variant(dims, ua.VariantType.UInt32)))
    await node.add_method(nid("Stop"), ua.QualifiedName("Stop", idx), stop, [],
                          [REASON_ARGUMENT])
    return ProcessNode(node, state, reason, frames, data)
