"""One contract, run over every registered service kind (as scikit-learn's common
estimator checks run over every estimator): what any device service promises whatever it
drives.  A new kind in ``apps/kinds.py`` is checked here without a line more.

Static, for every kind: the device class is no framework subclass and declares (a
:class:`~plugcell.framework.declaration.Declaration`) its kind, a valid default name,
vendor and info, a catalogue the framework accepts, and parameters ``plugcell serve``
can convert.
Running, for every kind that runs without outside hardware (simulated drivers): ``Get``
answers the declared catalogue; an unknown command, data of the wrong size and a
malformed request each end Failed with a precise reason — or are dropped — and the
service keeps serving.
"""

from __future__ import annotations

import asyncio
import uuid
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from controller_start import start_with_controller

from plugcell.apps.kinds import KINDS, build, load_kind
from plugcell.framework import Client, Participant, ProcessStates
from plugcell.framework.data import to_data
from plugcell.framework.declaration import Declaration
from plugcell.framework.keys import check_name
from plugcell.framework.messages import Command, DataTypes
from plugcell.framework.service import check_catalogue

#: How each kind runs here without hardware: its parameters (as ``--param``; a kind with
#: a driver interface gets its simulated driver from ``apps/kinds.build``, as served).
#: A kind missing from this table fails test_every_kind_can_be_run_or_says_why.
RUNNABLE: dict[str, dict[str, Any]] = {
    "camera": {"time_scale": 0.0},
    "drill": {"time_scale": 0.0},
    "bench": {},
    "tracker": {"driver": "sim"},
    "compute": {},
    "cell-controller": {"journals": 0},
    "robot": {"sim": True, "speed": 100.0},
}
#: Kinds whose default driver needs a partner outside plugcell: each runs here with
#: another implementation of its driver interface (test_opcua_device_keeps_the_contract;
#: tests/opcua run the default one against node-opcua).
NEEDS_OUTSIDE = {"opcua-device": "an OPC UA server (here: sim/drivers/opcua.py's model)"}
#: Kinds whose catalogue, vendor and info each instance declares (from its device map).
PER_INSTANCE = {"opcua-device"}

F = ProcessStates.Failed


def test_every_kind_can_be_run_or_says_why():
    assert set(KINDS) == set(RUNNABLE) | set(NEEDS_OUTSIDE)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_class_declares_what_every_service_has(kind):
    cls = load_kind(kind)
    assert not issubclass(cls, Participant), f"{kind}: a device is hosted, not derived"
    declared = cls.declaration
    assert isinstance(declared, Declaration)
    assert declared.kind == kind
    check_name(declared.name(), "default name")
    assert isinstance(declared.info, str) and declared.info
    assert isinstance(declared.vendor, str) and (declared.vendor or kind in PER_INSTANCE)
    assert declared.commands or kind in PER_INSTANCE, f"{kind}: no commands"
    check_catalogue(cls.__name__, declared.commands)  # raises with the reason
    for c in declared.commands:
        assert isinstance(c, Command) and c.timeout > 0, c
    for key, convert in getattr(cls, "params", {}).items():
        assert key.isidentifier() and callable(convert), (kind, key)


def _fixed_input(commands: tuple[Command, ...]) -> Command | None:
    """A command with a declared, fixed input size (to send the wrong size to)."""
    for c in commands:
        size = c.input_data_size  # () takes any size, -1 any length along an axis
        if c.input_data_type is not None and size and size != (0,) and all(
                n > 0 for n in size):
            return c
    return None


_SAMPLE = {DataTypes.Double: 0.0, DataTypes.Integer: 0, DataTypes.Byte: 0,
           DataTypes.Boolean: False, DataTypes.String: "x"}


async def _contract(kind: str, kwargs: dict[str, Any], cell: str, tmp_path,
                    device: Any = None, service: Any = None) -> None:
    """The contract of a running service; ``device()``, if given, starts the device it
    drives once the service listens (a robot streaming to it); ``service``: the service
    (default: ``kind`` built as ``plugcell serve`` builds it)."""
    if service is None:
        service = build(kind, None, kwargs, cell=cell, journal=tmp_path / "journal")
    if device is None:
        await service.start()
    else:  # a robot streaming to it: started once the service's link listens
        await start_with_controller(service, SimpleNamespace(start=device))
    name = service.name
    try:
        async with Client("CONFORMANCE", cell=cell) as client:
            assert await client.wait_for(name, 20)
            state, instance = await client.get(name)
            assert instance == service.participant.instance
            declared = {c.name for c in service.declaration.commands}
            assert {c.name for c in state.device_info.commands} == declared

            # an unknown command: Failed, naming it; the service carries on
            final = await (await client.create_process(name, "NoSuchCommand", check=False)
                           ).result()
            assert final.state is F and "NoSuchCommand" in final.reason

            # data of the wrong size for a command that declares its input
            c = _fixed_input(service.declaration.commands)
            if c is not None:
                n = int(np.prod(c.input_data_size)) + 1
                wrong = to_data([_SAMPLE[c.input_data_type]] * n, c.input_data_type, (n,))
                final = await (await client.create_process(name, c.name, data=wrong,
                                                           check=False)).result()
                assert final.state is F and c.name in final.reason, final.reason

            # a malformed request on the service's request key: dropped, nothing breaks
            assert client.session is not None
            client.session.put(client.keys.request(name, client.name), b"\x00not msgpack")
            await asyncio.sleep(0.2)
            state, again = await client.get(name)
            assert again == instance and not service.stopped.is_set()
    finally:
        await service.close()


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(RUNNABLE))
def test_a_running_service_keeps_the_contract(kind, tmp_path, monkeypatch):
    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    cell = f"conf{uuid.uuid4().hex[:10]}"
    asyncio.run(asyncio.wait_for(_contract(kind, RUNNABLE[kind], cell, tmp_path),
                                 90))


@pytest.mark.slow
def test_opcua_device_keeps_the_contract(tmp_path, monkeypatch):
    """The OPC UA device with the gripper of the tests behind the in-memory server model
    (its other driver, sim/drivers/opcua.py), hosted as ``plugcell serve`` hosts it."""
    from pathlib import Path

    from plugcell.devices.opcua.device import OpcUaDevice
    from plugcell.framework import GenericDevice
    from plugcell.sim.drivers.opcua import OpcUaServerModel, SimulatedGripper, SimulatedOpcUaDriver

    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    cell = f"conf{uuid.uuid4().hex[:10]}"
    server = OpcUaServerModel()
    SimulatedGripper(server)
    gripper_map = Path(__file__).resolve().parents[1] / "opcua" / "gripper.toml"
    service = GenericDevice(OpcUaDevice(SimulatedOpcUaDriver(server), map=gripper_map),
                            cell=cell, journal=tmp_path / "journal")
    asyncio.run(asyncio.wait_for(_contract("opcua-device", {}, cell, tmp_path,
                                           service=service), 90))


@pytest.mark.slow
@pytest.mark.parametrize("vendor", ["rsi", "egm"])
def test_the_robot_streamed_from_the_pc_keeps_the_contract(vendor, tmp_path, monkeypatch):
    """The robot kind with its programs on the PC and the twin's RSI or EGM side as the
    robot (a controller timeout of 4 s each: this machine is shared)."""
    import socket

    from plugcell.sim.controller.egm_twin import EgmTwinProcess
    from plugcell.sim.controller.rsi_twin import RsiTwinProcess

    monkeypatch.setenv("PLUGCELL_HOME", str(tmp_path / "home"))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cell = f"conf{uuid.uuid4().hex[:10]}"
    twin, timeout = ((RsiTwinProcess, {"rsi_timeout": 1000}) if vendor == "rsi" else
                     (EgmTwinProcess, {"egm_timeout": 4.0}))
    robot = twin(f"127.0.0.1:{port}", "--timeout", str(next(iter(timeout.values()))))
    try:
        asyncio.run(asyncio.wait_for(_contract(
            "robot", {vendor: f"127.0.0.1:{port}", **timeout}, cell, tmp_path, robot.start),
            90))
    finally:
        robot.kill()
