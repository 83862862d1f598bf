"""Robots in the gateway's address space as OPC 40010 (Robotics) types them.

A service of kind ``robot`` (its catalogue has ``ARM_JNTP`` and ``ARM_POS``) becomes a
``MotionDeviceSystemType`` in DI's ``DeviceSet`` (layout:
:mod:`plugcell.devices.opcua.companion`): one ``MotionDeviceType`` (category
ARTICULATED_ROBOT) with one ``AxisType`` per joint and one ``PowerTrainType`` (with its
motor) moving each axis, one ``ControllerType`` whose software is the robot service, and
one ``SafetyStateType``.  Their DI identification (Manufacturer, Model, ProductCode,
SerialNumber) is the robot service's ``IDENTIFICATION`` answer when it has one (from the
robot description file's ``[identification]`` table), else its DeviceInfo (vendor,
kind).

The mirror asks the robot service for ``ARM_JNTP`` and ``ARM_POS`` every ``period``
seconds (two processes each time, journaled like any other, sent by the gateway's
participant) and writes

* each axis's ``ParameterSet/ActualPosition`` (°), the joint reading;
* each axis's ``ParameterSet/ActualSpeed`` (°/s), the mean speed since the previous
  reading, ``(q_k − q_{k−1}) / (t_k − t_{k−1})`` (the robot service reports positions
  only; Null with ``BadWaitingForInitialData`` until two readings);
* ``FlangePose`` (Double[6]: x, y, z mm, a, b, c ° ZYZ in the robot base; the robot
  service's ``ARM_POS``; OPC 40010 has no flange pose variable).

The axes are made on the first answer (their number is the robot's).  A refused or
failed read leaves the values and sets their status ``BadCommunicationError``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from datetime import UTC, datetime

from asyncua import Node, Server, ua

from plugcell.devices.opcua.address_space import ServiceNode
from plugcell.devices.opcua.companion import (
    ARTICULATED_ROBOT,
    DEGREE,
    DEGREE_PER_SECOND,
    ROTARY,
    Models,
    add_instance,
    child,
    identify,
    not_supported,
    set_value,
)
from plugcell.framework.data import from_data
from plugcell.framework.messages import Device, ProcessStates
from plugcell.framework.participant import Participant

log = logging.getLogger("plugcell.devices.opcua")

REQUIRED = ("ARM_JNTP", "ARM_POS")
#: The optional command of a robot service that names its robot (String[4]:
#: manufacturer, model, serial number, product code).
IDENTIFICATION = "IDENTIFICATION"


def _version() -> str:
    """plugcell's version, as installed ("" when run from a tree that is not)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("plugcell")
    except PackageNotFoundError:
        return ""


def is_robot(device: Device) -> bool:
    """Whether a service is a robot the gateway mirrors (kind robot, ARM_JNTP, ARM_POS)."""
    return device.kind == "robot" and all(device.command(c) is not None for c in REQUIRED)


class RobotMirror:
    """The OPC 40010 nodes of one robot service and the task that keeps them current."""

    def __init__(self, server: Server, models: Models, service: ServiceNode, device: Device,
                 caller: Participant, period: float) -> None:
        self.server = server
        self.models = models
        self.service = service
        self.device = device
        self.caller = caller
        self.period = period
        self.system: Node | None = None
        self.motion_device: Node | None = None
        self.positions: list[Node] = []
        self.speeds: list[Node] = []
        self.flange: Node | None = None
        self._last: tuple[datetime, list[float]] | None = None
        self._complained = False

    async def run(self) -> None:
        """Build the MotionDeviceSystem, then poll until cancelled (a failed poll is
        logged and the next one tried; no polls with a period 0)."""
        await self.build()
        while self.period > 0:
            try:
                await self.poll()
            except Exception:  # e.g. the service's nodes went away meanwhile
                log.debug("opcua: poll of %s failed", self.service.name, exc_info=True)
            await asyncio.sleep(self.period)

    # -- the nodes -------------------------------------------------------------------

    async def build(self) -> None:
        """The MotionDeviceSystem without its axes (made on the first joint reading)."""
        m, name, rob = self.models, self.service.name, self.models.robotics
        manufacturer, model, serial, product = await self._identification()
        system = self.system = await add_instance(m, m.device_set, name,
                                                  "MotionDeviceSystemType")
        self.service.device = system
        await system.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText(f"robot service {name}: {self.device.info}"),
            ua.VariantType.LocalizedText)))
        motion = self.motion_device = await add_instance(
            m, await child(system, f"{rob}:MotionDevices"), name, "MotionDeviceType")
        await identify(m, motion, manufacturer, model, serial, product)
        await set_value(await child(motion, f"{rob}:MotionDeviceCategory"), ARTICULATED_ROBOT,
                        ua.VariantType.Int32)
        await not_supported(await child(motion, f"{m.di}:ParameterSet", f"{rob}:SpeedOverride"))
        controller = await add_instance(m, await child(system, f"{rob}:Controllers"),
                                        "Controller", "ControllerType")
        await identify(m, controller, manufacturer, f"{model} controller", serial, product)
        software = await add_instance(m, await child(controller, f"{rob}:Software"),
                                      "RobotService", "SoftwareType")
        await identify(m, software, "plugcell", "plugcell robot service")
        await set_value(await child(software, f"{m.di}:SoftwareRevision"), _version(),
                        ua.VariantType.String)
        await add_instance(m, await child(controller, f"{rob}:TaskControls"), "Program",
                           "TaskControlType")
        safety = await add_instance(m, await child(system, f"{rob}:SafetyStates"), "Safety",
                                    "SafetyStateType")
        for key in ("EmergencyStop", "OperationalMode", "ProtectiveStop"):
            await not_supported(await child(safety, f"{m.di}:ParameterSet", f"{rob}:{key}"))

    async def _identification(self) -> tuple[str, str, str, str]:
        if self.device.command(IDENTIFICATION) is not None:
            call = await self.caller.create_process(self.service.name, IDENTIFICATION,
                                                    timeout=5.0)
            final = await call.result()
            values = from_data(final.data) if final.state is ProcessStates.Completed else None
            if values is not None and values.size >= 4:
                text = [str(v) for v in values.reshape(-1)[:4]]
                return text[0], text[1], text[2], text[3]
            log.warning("opcua: %s IDENTIFICATION failed (%s); DI identification from its "
                        "DeviceInfo", self.service.name, final.reason)
        return self.device.vendor, self.device.kind, "", ""

    async def _make_axes(self, count: int) -> None:
        m, rob = self.models, self.models.robotics
        assert self.motion_device is not None
        axes = await child(self.motion_device, f"{rob}:Axes")
        trains = await child(self.motion_device, f"{rob}:PowerTrains")
        for k in range(1, count + 1):
            axis = await add_instance(m, axes, f"Axis{k}", "AxisType")
            await set_value(await child(axis, f"{rob}:MotionProfile"), ROTARY,
                            ua.VariantType.Int32)
            params = await child(axis, f"{m.di}:ParameterSet")
            position = await child(params, f"{rob}:ActualPosition")
            await set_value(await child(position, "0:EngineeringUnits"), DEGREE,
                            ua.VariantType.ExtensionObject)
            speed = await params.add_variable(
                ua.NodeId(f"{params.nodeid.Identifier}.ActualSpeed", m.idx),
                ua.QualifiedName("ActualSpeed", rob), ua.Variant(0.0, ua.VariantType.Double),
                datatype=ua.NodeId(ua.ObjectIds.Double))
            # an AnalogUnitType (as AxisType declares ActualSpeed), not asyncua's default type
            await speed.delete_reference(ua.NodeId(ua.ObjectIds.BaseDataVariableType),
                                         ua.ObjectIds.HasTypeDefinition)
            await speed.add_reference(ua.NodeId(ua.ObjectIds.AnalogUnitType),
                                      ua.ObjectIds.HasTypeDefinition)
            await speed.add_property(
                ua.NodeId(f"{speed.nodeid.Identifier}.EngineeringUnits", m.idx),
                ua.QualifiedName("EngineeringUnits", 0),
                ua.Variant(DEGREE_PER_SECOND, ua.VariantType.ExtensionObject),
                datatype=ua.NodeId(ua.ObjectIds.EUInformation))
            await speed.write_value(ua.DataValue(
                StatusCode=ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData)))
            train = await add_instance(m, trains, f"PowerTrain{k}", "PowerTrainType")
            await add_instance(m, train, f"Motor{k}", "MotorType")
            await train.add_reference(axis.nodeid, m.moves)
            self.positions.append(position)
            self.speeds.append(speed)
        self.flange = await self.motion_device.add_variable(
            ua.NodeId(f"{self.motion_device.nodeid.Identifier}.FlangePose", m.idx),
            ua.QualifiedName("FlangePose", m.idx),
            ua.Variant([0.0] * 6, ua.VariantType.Double, is_array=True))
        await self.flange.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText("flange pose x, y, z mm, a, b, c deg (ZYZ) in the robot base"),
            ua.VariantType.LocalizedText)))

    # -- the values ------------------------------------------------------------------

    async def poll(self) -> None:
        joints = await self._read("ARM_JNTP")
        pose = await self._read("ARM_POS")
        if joints is not None and not self.positions:
            await self._make_axes(len(joints))
        now = datetime.now(UTC)
        speeds: list[float] | None = None
        if joints is not None:
            if self._last is not None and len(self._last[1]) == len(joints):
                dt = (now - self._last[0]).total_seconds()
                if dt > 0:
                    speeds = [(q - p) / dt for q, p in zip(joints, self._last[1], strict=True)]
            self._last = (now, joints)
        for i, node in enumerate(self.positions):
            await self._write(node, None if joints is None or i >= len(joints)
                              else ua.Variant(joints[i], ua.VariantType.Double), now)
            if speeds is not None and i < len(speeds):
                await self._write(self.speeds[i], ua.Variant(speeds[i], ua.VariantType.Double),
                                  now)
            elif joints is None:
                await self._write(self.speeds[i], None, now)
        if self.flange is not None:
            await self._write(self.flange, None if pose is None else ua.Variant(
                pose, ua.VariantType.Double, is_array=True), now)

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
        with contextlib.suppress(ua.UaStatusCodeError):
            await self.server.write_attribute_value(node.nodeid, value)
