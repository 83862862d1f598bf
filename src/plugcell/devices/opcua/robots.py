"""Robots in the gateway's address space, named as OPC 40010 (Robotics) names them.

A service of kind ``robot`` (its catalogue has ``ARM_JNTP`` and ``ARM_POS``) plays the
*MotionDevice* of OPC 40010: below its object the gateway adds ::

    Axes/                                   FolderType (MotionDeviceType.Axes)
      Axis1 … AxisN/                        one per joint (AxisType)
        ParameterSet/ActualPosition         Double, deg (AxisType ParameterSet)
    FlangePose                              Double[6]: x, y, z mm, a, b, c deg (ZYZ), the
                                            robot service's ARM_POS (OPC 40010 has no
                                            flange pose variable; named for what it is)

and keeps them current by asking the robot service for ``ARM_JNTP`` and ``ARM_POS``
every ``period`` seconds (two processes each time, journaled like any other, sent by the
gateway's participant).  The axes are made on the first answer (their number is the
robot's).  A refused or failed read leaves the values and sets their status Bad.
"""

from __future__ import annotations

import asyncio
import logging
from datetime import UTC, datetime

from asyncua import Node, Server, ua

from plugcell.devices.opcua.address_space import ServiceNode, node_id
from plugcell.framework.data import from_data
from plugcell.framework.messages import Device, ProcessStates
from plugcell.framework.participant import Participant

log = logging.getLogger("plugcell.devices.opcua")

REQUIRED = ("ARM_JNTP", "ARM_POS")


def is_robot(device: Device) -> bool:
    """Whether a service is a robot the gateway mirrors (kind robot, ARM_JNTP, ARM_POS)."""
    return device.kind == "robot" and all(device.command(c) is not None for c in REQUIRED)


class RobotMirror:
    """The OPC 40010 nodes of one robot service and the task that keeps them current."""

    def __init__(self, server: Server, service: ServiceNode, caller: Participant,
                 period: float) -> None:
        self.server = server
        self.service = service
        self.caller = caller
        self.period = period
        self.axes: list[Node] = []
        self.flange: Node | None = None
        self._complained = False

    async def run(self) -> None:
        """Poll until cancelled (a failed poll is logged and the next one tried)."""
        while True:
            try:
                await self.poll()
            except Exception:  # e.g. the service's nodes went away meanwhile
                log.debug("opcua: poll of %s failed", self.service.name, exc_info=True)
            await asyncio.sleep(self.period)

    async def poll(self) -> None:
        joints = await self._read("ARM_JNTP")
        pose = await self._read("ARM_POS")
        if joints is not None and not self.axes:
            await self._make_nodes(len(joints))
        now = datetime.now(UTC)
        for i, axis in enumerate(self.axes):
            await self._write(axis, None if joints is None or i >= len(joints)
                              else ua.Variant(float(joints[i]), ua.VariantType.Double), now)
        if self.flange is not None:
            await self._write(self.flange, None if pose is None else ua.Variant(
                [float(v) for v in pose], ua.VariantType.Double, is_array=True), now)

    async def _read(self, command: str) -> list[float] | None:
        name = self.service.name
        call = await self.caller.create_process(name, command, timeout=5.0)
        final = await call.result()
        if final.state is not ProcessStates.Completed:
            if not self._complained:
                log.warning("opcua: %s %s for the OPC 40010 mirror failed: %s", name, command,
                            final.reason)
                self._complained = True
            return None
        values = from_data(final.data)
        return None if values is None else [float(v) for v in values.reshape(-1)]

    async def _write(self, node: Node, variant: ua.Variant | None, now: datetime) -> None:
        if variant is None:
            value = ua.DataValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadCommunicationError),
                                 SourceTimestamp=now, ServerTimestamp=now)
        else:
            value = ua.DataValue(variant, SourceTimestamp=now, ServerTimestamp=now)
        await self.server.write_attribute_value(node.nodeid, value)

    async def _make_nodes(self, count: int) -> None:
        svc = self.service
        idx, name = svc.idx, svc.name
        axes = await svc.node.add_folder(node_id(idx, name, "Axes"), ua.QualifiedName("Axes", idx))
        for k in range(1, count + 1):
            axis = f"Axis{k}"
            obj = await axes.add_object(node_id(idx, name, "Axes", axis),
                                        ua.QualifiedName(axis, idx))
            params = await obj.add_object(node_id(idx, name, "Axes", axis, "ParameterSet"),
                                          ua.QualifiedName("ParameterSet", idx))
            position = await params.add_variable(
                node_id(idx, name, "Axes", axis, "ParameterSet", "ActualPosition"),
                ua.QualifiedName("ActualPosition", idx), ua.Variant(0.0, ua.VariantType.Double))
            await position.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
                ua.LocalizedText(f"joint {k} angle, deg"), ua.VariantType.LocalizedText)))
            self.axes.append(position)
        self.flange = await svc.node.add_variable(
            node_id(idx, name, "FlangePose"), ua.QualifiedName("FlangePose", idx),
            ua.Variant([0.0] * 6, ua.VariantType.Double, is_array=True))
        await self.flange.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText("flange pose x, y, z mm, a, b, c deg (ZYZ) in the robot base"),
            ua.VariantType.LocalizedText)))
