"""The OPC UA device behind its driver interface (issue 33): the service takes any
:class:`~plugcell.devices.opcua.driver.OpcUaDriver`.  Here a second implementation — a
client of an in-memory OPC UA server model (``sim/drivers/opcua.py``) holding the
gripper of tests/opcua/js/gripper_server.js — runs the same device map through the same
service as the asyncua client does against node-opcua (test_opcua_device.py): the
same checks of the map, the same reasons, the same lost-and-found connection."""

from __future__ import annotations

import asyncio
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.kinds import build
from plugcell.devices.opcua.arguments import VARIANT_TYPES
from plugcell.devices.opcua.client import AsyncuaDriver
from plugcell.devices.opcua.device import OpcUaDevice
from plugcell.devices.opcua.device_map import parse_device_map
from plugcell.devices.opcua.driver import OpcUaDriver, OpcUaStatusError, OpcUaValue
from plugcell.framework import Client, DeviceError, GenericDevice, ProcessStates
from plugcell.framework.messages import DataTypes
from plugcell.sim.drivers.opcua import (
    GRIPPER_NAMESPACE,
    OpcUaServerModel,
    SimulatedGripper,
    SimulatedOpcUaDriver,
)

HERE = Path(__file__).resolve().parent
NS = GRIPPER_NAMESPACE
MAP = HERE / "gripper.toml"
C, F = ProcessStates.Completed, ProcessStates.Failed


def _device(text: str | None = None, server: OpcUaServerModel | None = None,
            watch_s: float = 1.0) -> tuple[OpcUaDevice, OpcUaServerModel]:
    server = server or OpcUaServerModel("opc.tcp://gripper.sim:4840/gripper")
    if not server.namespaces[1:]:
        SimulatedGripper(server)
    device_map = (parse_device_map(text, "device.toml") if text is not None else MAP)
    device = GenericDevice(OpcUaDevice(SimulatedOpcUaDriver(server), map=device_map,
                                       watch_s=watch_s), "GRIPPER", journal=False).interface
    return device, server


def test_both_drivers_have_the_interface_and_serve_gives_the_asyncua_one():
    server = OpcUaServerModel()
    assert isinstance(SimulatedOpcUaDriver(server), OpcUaDriver)
    asyncua = AsyncuaDriver(endpoint="opc.tcp://127.0.0.1:4840", insecure_accept_any=True)
    assert isinstance(asyncua, OpcUaDriver)
    service = build("opcua-device", None, {"endpoint": "opc.tcp://plc:4840", "map": str(MAP),
                                           "insecure_accept_any": True, "watch_s": 0.5},
                    journal=False)
    device = service.interface
    assert isinstance(device.driver, AsyncuaDriver) and device.watch_s == 0.5
    assert (device.driver.endpoint, device.driver.insecure_accept_any) == ("opc.tcp://plc:4840",
                                                                           True)
    assert service.name == "GRIPPER"
    with pytest.raises(ValueError, match="opcua-device needs --map FILE"):
        OpcUaDevice(SimulatedOpcUaDriver(server))
    with pytest.raises(ValueError, match="opcua-device needs --endpoint"):
        AsyncuaDriver(insecure_accept_any=True)


def test_the_data_type_numbers_are_opc_uas():
    from asyncua import ua

    asyncuas = {DataTypes.Boolean: ua.VariantType.Boolean, DataTypes.Byte: ua.VariantType.Byte,
                DataTypes.Integer: ua.VariantType.Int32, DataTypes.Double: ua.VariantType.Double,
                DataTypes.String: ua.VariantType.String}
    assert dict(VARIANT_TYPES) == asyncuas


def test_the_map_is_resolved_and_each_bad_map_refused_with_the_reason():
    async def body() -> list[str]:
        device, server = _device()
        await device._open()
        assert device.connected and server.sessions == ["GRIPPER"]
        assert device._nodes["Close"].node.node_id == "ns=2;s=Gripper.Close"
        assert device._nodes["Close"].object.browse_name == "Gripper"
        await device._close_client()
        text = MAP.read_text()
        reasons = []
        for bad in (
            text.replace("s=Gripper.Open", "s=Gripper.Twist"),
            text.replace(f"{NS};s=Gripper.Force", "urn:nowhere;s=Gripper.Force"),
            text.replace(f'read = "nsu={NS};s=Gripper.Force"\noutput = {{ type = "Double"',
                         f'read = "nsu={NS};s=Gripper.Force"\noutput = {{ type = "Integer"'),
            text.replace(f'read = "nsu={NS};s=Gripper.Force"', f'read = "nsu={NS};s=Gripper.Open"'),
            text.replace(f'object = "nsu={NS};s=Gripper"', f'object = "nsu={NS};s=Gripper.Hand"'),
        ):
            device, _ = _device(bad, server)
            with pytest.raises(DeviceError) as err:
                await device._open()
            assert not device.connected
            reasons.append(str(err.value))
        server.stop()
        device, _ = _device(None, server)
        with pytest.raises(DeviceError) as err:
            await device._open()
        reasons.append(str(err.value))
        return reasons

    reasons = asyncio.run(body())
    where = "device.toml: command"
    assert reasons[0] == (f"{where} 'Open': method nsu={NS};s=Gripper.Twist does not exist on "
                          "opc.tcp://gripper.sim:4840/gripper (BadNodeIdUnknown)")
    assert reasons[1] == (f"{where} 'Force': read nsu=urn:nowhere;s=Gripper.Force: the server "
                          "has no namespace urn:nowhere")
    assert reasons[2] == (f"{where} 'Force': variable nsu={NS};s=Gripper.Force holds i=11, but "
                          "the map declares Integer (i=6)")
    assert reasons[3] == f"{where} 'Force': nsu={NS};s=Gripper.Open is a Method, not a Variable"
    assert reasons[4].startswith(f"{where} 'Open': object nsu={NS};s=Gripper.Hand does not "
                                 "exist")
    assert reasons[5] == ("cannot connect to opc.tcp://gripper.sim:4840/gripper: "
                          "opc.tcp://gripper.sim:4840/gripper refused the connection")


def test_the_server_model_refuses_as_a_server_does():
    async def body() -> None:
        server = OpcUaServerModel()
        gripper = SimulatedGripper(server)
        driver = SimulatedOpcUaDriver(server)
        with pytest.raises(ConnectionError, match="no session"):
            await driver.read(gripper.force)
        await driver.connect("T", 2.0)
        obj = await driver.parent(await driver.find("ns=2;s=Gripper.Close"))
        close = await driver.find("ns=2;s=Gripper.Close")
        double = OpcUaValue(30.0, DataTypes.Double)
        for call, status in (
            (driver.find("ns=2;s=Nothing"), "BadNodeIdUnknown"),
            (driver.find("no id"), "BadNodeIdInvalid"),
            (driver.read(close), "BadAttributeIdInvalid"),
            (driver.data_type(obj), "BadAttributeIdInvalid"),
            (driver.write(gripper.force, OpcUaValue(3, DataTypes.Integer)), "BadTypeMismatch"),
            (driver.write(gripper.force, OpcUaValue([1.0], DataTypes.Double, True)),
             "BadTypeMismatch"),
            (driver.call(obj, close, []), "BadArgumentsMissing"),
            (driver.call(obj, close, [double, double]), "BadTooManyArguments"),
            (driver.call(obj, close, [OpcUaValue("30", DataTypes.String)]), "BadTypeMismatch"),
            (driver.call(server.objects, close, [double]), "BadMethodInvalid"),
            (driver.call(obj, gripper.force, [double]), "BadMethodInvalid"),
            (driver.call(obj, close, [OpcUaValue(500.0, DataTypes.Double)]), "BadOutOfRange"),
        ):
            with pytest.raises(OpcUaStatusError) as err:
                await call
            assert err.value.status == status
        assert await driver.call(obj, close, [double]) == [30.0]
        assert await driver.read(gripper.closed) is True
        assert server.calls == [("Close", [500.0]), ("Close", [30.0])]
        server.stop()
        with pytest.raises(ConnectionError, match="closed the connection"):
            await driver.server_state()
        server.start()  # a session of the server before its restart stays gone
        with pytest.raises(ConnectionError, match="closed the connection"):
            await driver.read(gripper.force)
        await driver.connect("T", 2.0)
        assert await driver.server_state() == 0

    asyncio.run(body())


WRITE_MAP = f"""
[device]
name = "GRIPPER"
object = "nsu={NS};s=Gripper"

[[command]]
name = "SetLimits"
type = "NoData"
write = "nsu={NS};s=Gripper.Limits"
input = {{ type = "Double", size = [2] }}

[[command]]
name = "Limits"
type = "SingleData"
read = "nsu={NS};s=Gripper.Limits"
output = {{ type = "Double", size = [2] }}
"""


async def _process(client: Client, command: str, data: Any = None, option: str = ""):
    return await (await client.create_process("GRIPPER", command, option, data,
                                              timeout=20.0)).result()


@pytest.mark.slow
def test_the_service_drives_the_gripper_through_the_second_driver():
    """Method calls (a refusal's status code in the reason), reads, an array written and
    read back, a stream of value changes ended by StopData — over the cell, as served."""
    async def body() -> None:
        cell = f"uadrv{uuid.uuid4().hex[:8]}"
        server = OpcUaServerModel("opc.tcp://gripper.sim:4840/gripper")
        gripper = SimulatedGripper(server)
        creep = asyncio.create_task(gripper.creep())
        services = [GenericDevice(OpcUaDevice(SimulatedOpcUaDriver(server), map=m),
                                  name, cell=cell, journal=False)
                    for name, m in (("GRIPPER", MAP),
                                    ("LIMITS", parse_device_map(WRITE_MAP, "write.toml")))]
        for service in services:
            await service.start()
        try:
            async with Client("tester", cell=cell) as client:
                assert await client.wait_for("GRIPPER", 10) and await client.wait_for("LIMITS")
                closed = await _process(client, "Close", [20.0])
                assert closed.state is C, closed.reason
                assert _array(closed).tolist() == [20.0]
                refused = await _process(client, "Close", [500.0])
                assert refused.state is F
                assert "the server answered BadOutOfRange: force 500.0 N outside (0, 100]" \
                    in refused.reason, refused.reason
                force = await _process(client, "Force")
                assert force.state is C and _array(force)[0] >= 20.0

                stream = await client.create_process("GRIPPER", "WatchForce", timeout=20.0)
                values = []
                async for update in stream:
                    if update.data is not None:
                        values.append(float(_array(update)[0]))
                    if len(values) == 3:
                        break
                assert values == sorted(values) and values[0] >= 20.0  # it creeps
                await client.stop_process(stream)
                assert (await stream.result()).state is C
                assert (await _process(client, "Open")).state is C
                assert gripper.force.value == 0.0 and gripper.closed.value is False

                limits = await (await client.create_process(
                    "LIMITS", "SetLimits", data=[5.0, 80.0], timeout=20.0)).result()
                assert limits.state is C, limits.reason
                read = await (await client.create_process("LIMITS", "Limits")).result()
                np.testing.assert_array_equal(_array(read), [5.0, 80.0])
                assert gripper.limit.value == [5.0, 80.0]
            assert [name for name, _ in server.calls] == ["Close", "Close", "Open"]
        finally:
            creep.cancel()
            for service in services:
                await service.close()

    asyncio.run(asyncio.wait_for(body(), 60))


@pytest.mark.slow
def test_a_lost_server_fails_the_stream_and_the_service_reconnects():
    async def body() -> None:
        cell = f"uadrv{uuid.uuid4().hex[:8]}"
        endpoint = "opc.tcp://gripper.sim:4840/gripper"
        server = OpcUaServerModel(endpoint)
        gripper = SimulatedGripper(server)
        creep = asyncio.create_task(gripper.creep())
        service = GenericDevice(OpcUaDevice(SimulatedOpcUaDriver(server), map=MAP,
                                            watch_s=0.2), "GRIPPER", cell=cell, journal=False)
        await service.start()
        try:
            async with Client("watcher", cell=cell) as client:
                assert await client.wait_for("GRIPPER", 10)
                assert (await _process(client, "Close", [10.0])).state is C
                stream = await client.create_process("GRIPPER", "WatchForce", timeout=20.0)
                frames = 0
                async for update in stream:
                    frames += update.data is not None
                    if frames == 2:
                        break
                server.stop()  # the device's server goes away
                final = await stream.result()
                assert final.state is F
                assert final.reason.startswith(
                    f"WatchForce: device feedback 'connection to {endpoint} lost: ") \
                    and final.reason.endswith("' while streaming"), final.reason
                down = await _process(client, "Force")
                assert down.state is F and f"connection to {endpoint} lost" in down.reason
                assert (await client.get("GRIPPER"))[0].device_info.connection.value == "Error"
                server.start()
                for _ in range(100):
                    if (await _process(client, "Force")).state is C:
                        break
                    await asyncio.sleep(0.1)
                state = (await client.get("GRIPPER"))[0]
                assert state.device_info.connection.value == "Online"
            assert server.sessions == ["GRIPPER", "GRIPPER"]
        finally:
            creep.cancel()
            await service.close()

    asyncio.run(asyncio.wait_for(body(), 60))


def _array(update: Any) -> np.ndarray:
    from plugcell.framework import ProcessCall

    return np.asarray(ProcessCall.array(update)).reshape(-1)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=40))
def test_any_node_id_text_is_found_or_refused_with_a_status(text):
    """The model parses a node id as a server does: a node, or BadNodeIdInvalid /
    BadNodeIdUnknown — never another error."""
    server = OpcUaServerModel()
    SimulatedGripper(server)
    try:
        node = server.node(text)
    except OpcUaStatusError as exc:
        assert exc.status in ("BadNodeIdInvalid", "BadNodeIdUnknown")
    else:
        assert node.node_id in (text, text.removeprefix("ns=0;"))


_ELEMENTS = {
    DataTypes.Double: st.floats(allow_nan=False, width=64),
    DataTypes.Integer: st.integers(-2**31, 2**31 - 1),
    DataTypes.Boolean: st.booleans(),
    DataTypes.Byte: st.integers(0, 255),
    DataTypes.String: st.text(max_size=8),
}


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(sorted(_ELEMENTS, key=lambda t: t.value)).flatmap(
    lambda t: st.tuples(st.just(t), st.lists(_ELEMENTS[t], min_size=1, max_size=6))))
def test_input_data_reaches_the_server_as_sent(case):
    """The device's input data (numpy, as the framework hands it) written through the
    driver and read back: the same values, a scalar for size (1,), a list for an array
    (size (-1,): any length)."""
    from plugcell.devices.opcua.device import _value

    data_type, values = case
    dtype = {DataTypes.Double: float, DataTypes.Integer: np.int32, DataTypes.Boolean: bool,
             DataTypes.Byte: np.uint8, DataTypes.String: object}[data_type]
    server = OpcUaServerModel()
    obj = server.add_object("ns=0;s=Box", "Box")
    scalar = server.add_variable("ns=0;s=Box.One", "One", obj, data_type, values[0])
    array = server.add_variable("ns=0;s=Box.Many", "Many", obj, data_type, values,
                                is_array=True)

    async def body() -> None:
        driver = SimulatedOpcUaDriver(server)
        await driver.connect("T", 1.0)
        await driver.write(scalar, _value(np.array(values[:1], dtype=dtype), data_type, (1,)))
        await driver.write(array, _value(np.array(values, dtype=dtype), data_type, (-1,)))
        assert await driver.read(scalar) == values[0]
        assert await driver.read(array) == values

    asyncio.run(body())
