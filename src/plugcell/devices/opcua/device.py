"""``plugcell serve opcua-device``: an OPC UA server's device as a plugcell service.

The service's catalogue is its device map (:mod:`plugcell.devices.opcua.device_map`); it
reaches the server through an :class:`~plugcell.devices.opcua.driver.OpcUaDriver` (``plugcell
serve opcua-device`` gives it the asyncua client of ``--endpoint``,
:class:`~plugcell.devices.opcua.client.AsyncuaDriver`):

* ``method`` commands call the method (input data — and the option, if the map
  says so — as its arguments; a SingleData command's data is its first output);
* ``write`` commands write their input to a variable;
* ``read`` commands read a variable (SingleData);
* ``subscribe`` commands stream a variable's value changes (an OPC UA
  subscription; MultipleData) until the sender's StopData deletes it.

At start the service connects and resolves every node of the map: a node that does
not exist, is of the wrong node class, or holds another data type than the map
declares stops it with the reason (the file, the command, the node).  Then a watch
reads the server's state every ``watch_s``: a lost connection makes the service
``ConnectionState Error``, fails a running stream (``device feedback 'connection to
… lost: …' while streaming``) and every command until the connection is back; the
service keeps reconnecting every ``watch_s`` and re-resolves the map each time (the
server's namespace indexes may have changed), then reports Online again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from plugcell.devices.opcua.device_map import DeviceMap, MappedCommand, load_device_map
from plugcell.devices.opcua.driver import (
    OpcUaDriver,
    OpcUaDriverError,
    OpcUaStatusError,
    OpcUaValue,
    data_type_id,
)
from plugcell.framework.declaration import Declaration
from plugcell.framework.messages import Command, ConnectionStates, DataTypes
from plugcell.framework.service import DeviceError, GenericDevice

log = logging.getLogger("plugcell.devices.opcua.device")

#: What a broken link raises through the driver (module docstring of .driver).
_LINK_ERRORS = (TimeoutError, OSError, ConnectionError)


@dataclass
class _Resolved:
    """The nodes of one mapped command on the connected server (driver handles)."""

    node: Any = None
    object: Any = None


class OpcUaDevice:
    """A device behind an OPC UA server, mapped to a catalogue by a device map (the device
    a :class:`~plugcell.framework.service.GenericDevice` hosts).

    Parameters
    ----------
    driver : OpcUaDriver
        The client of the device's server (``plugcell serve``: the asyncua one, with the
        ``endpoint``, ``certs``, ``user``, ``trust``, ``server_uri`` and
        ``insecure_accept_any`` parameters).
    map : str, Path or DeviceMap
        The device map: the catalogue, and the node each command acts on.
    watch_s : float
        How often the connection is checked (s); requests time out after twice that,
        at least 2 s.
    """

    declaration = Declaration(
        kind="opcua-device",
        info="an OPC UA device (plugcell serve opcua-device --endpoint … --map …)")
    """The kind's; each instance declares its map's catalogue, vendor and name."""
    params: ClassVar[dict[str, Any]] = {"map": str, "watch_s": float}

    def __init__(self, driver: OpcUaDriver, *, map: str | Path | DeviceMap = "",
                 watch_s: float = 1.0) -> None:
        if not map:
            raise ValueError("opcua-device needs --map FILE (docs/opcua.md)")
        if not watch_s > 0:
            raise ValueError(f"watch_s must be positive, not {watch_s}")
        self.driver = driver
        self.map = map if isinstance(map, DeviceMap) else load_device_map(map)
        # the catalogue and identity come from the map
        self.declaration = Declaration(
            kind=self.declaration.kind, commands=tuple(c.command for c in self.map.commands),
            default_name=self.map.name, vendor=self.map.vendor,
            info=self.map.info or f"OPC UA device at {driver.endpoint}")
        self.service: GenericDevice | None = None
        self.endpoint = driver.endpoint
        self.watch_s = watch_s
        self.connected = False
        """A session is open and the map resolved on it."""
        self._nodes: dict[str, _Resolved] = {}
        self._lost = ""
        """Why the connection is down ("" while connected)."""
        self._watch: asyncio.Task[None] | None = None
        self._subscription: Any = None

    def bind(self, service: GenericDevice) -> None:
        self.service = service

    @property
    def host(self) -> GenericDevice:
        """The service hosting this device."""
        assert self.service is not None, "OpcUaDevice used before a service hosts it"
        return self.service

    @property
    def name(self) -> str:
        """The service's name (the map's before a service hosts the device)."""
        return self.service.name if self.service is not None else self.declaration.name()

    # -- connection --------------------------------------------------------------------

    async def connect(self) -> None:
        """Connect and resolve the map (DeviceError with the reason if either fails)."""
        await self._open()
        self.host.connection_state.post(ConnectionStates.Online)
        self._watch = asyncio.create_task(self._watch_connection(), name=f"{self.name}-watch")

    async def _open(self) -> None:
        log.info("%s: connecting to %s", self.name, self.endpoint)
        try:
            await self.driver.connect(self.name, max(2.0, self.watch_s * 2))
        except (*_LINK_ERRORS, ValueError, OpcUaDriverError) as exc:
            raise DeviceError(f"cannot connect to {self.endpoint}: {_why(exc)}") from None
        try:
            self._nodes = {m.command.name: await self._resolve(m) for m in self.map.commands}
        except BaseException:
            with contextlib.suppress(Exception):
                await self.driver.disconnect()
            raise
        self.connected = True
        self._lost = ""

    async def disconnect(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watch
        await self._close_client()
        self.host.connection_state.post(ConnectionStates.Offline)

    async def _close_client(self) -> None:
        connected, self.connected, self._subscription = self.connected, False, None
        if connected:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self.driver.disconnect(), 2.0)

    async def _watch_connection(self) -> None:
        """Notice a lost connection, fail what runs, reconnect (module docstring)."""
        while True:
            await asyncio.sleep(self.watch_s)
            if self.connected:
                try:
                    await asyncio.wait_for(self.driver.server_state(), self.watch_s * 2)
                    continue
                except Exception as exc:  # any failure of the link is a lost connection
                    self._connection_lost(_why(exc))
                    await self._close_client()
            try:
                await self._open()
            except Exception as exc:
                self._lost = f"connection to {self.endpoint} lost: {_why(exc)} (reconnecting)"
                continue
            log.warning("%s: reconnected to %s", self.name, self.endpoint)
            self.host.connection_state.post(ConnectionStates.Online)

    def _connection_lost(self, why: str) -> None:
        self._lost = f"connection to {self.endpoint} lost: {why}"
        log.warning("%s: %s", self.name, self._lost)
        self.host.connection_state.post(ConnectionStates.Error)
        if self._subscription is not None:  # a stream is running: it ends Failed
            self.host.cmd_feedback.post(self._lost)

    # -- the map on the server ---------------------------------------------------------

    async def _resolve(self, mapped: MappedCommand) -> _Resolved:
        where = f"{self.map.source}: command {mapped.command.name!r}"
        if not mapped.action:
            return _Resolved()
        node = await self._node(mapped.node, where, mapped.action)
        want = "Method" if mapped.action == "method" else "Variable"
        if (cls := await self.driver.node_class(node)) != want:
            raise DeviceError(f"{where}: {mapped.node} is a {cls}, not a {want}")
        if mapped.action == "method":
            if mapped.object:
                obj = await self._node(mapped.object, where, "object")
            else:
                obj = await self.driver.parent(node)
                if obj is None:
                    raise DeviceError(f"{where}: method {mapped.node} has no parent object; "
                                      "name one with object = …")
            return _Resolved(node, obj)
        declared = (mapped.command.input_data_type if mapped.action == "write"
                    else mapped.command.output_data_type)
        assert declared is not None
        expected = data_type_id(declared)
        actual = await self.driver.data_type(node)
        if actual != expected:
            raise DeviceError(
                f"{where}: variable {mapped.node} holds {actual}, but the map "
                f"declares {declared.value} ({expected})")
        return _Resolved(node)

    async def _node(self, text: str, where: str, what: str) -> Any:
        """The node of a map's node id text (``nsu=`` resolved on this server)."""
        resolved = text
        if text.startswith("nsu="):
            uri, _, rest = text[4:].partition(";")
            try:
                idx = await self.driver.namespace_index(uri)
            except KeyError:
                raise DeviceError(f"{where}: {what} {text}: the server has no namespace "
                                  f"{uri}") from None
            resolved = f"ns={idx};{rest}"
        try:
            return await self.driver.find(resolved)
        except OpcUaStatusError as exc:
            raise DeviceError(f"{where}: {what} {text} does not exist on {self.endpoint} "
                              f"({exc.status})") from None

    # -- the device interface ----------------------------------------------------------

    async def dispatch(self, command: Command, option: str, data: Any) -> str:
        mapped = self.map.command(command.name)
        if self._lost or not self.connected:
            raise DeviceError(self._lost or f"not connected to {self.endpoint}")
        nodes = self._nodes[command.name]
        try:
            match mapped.action:
                case "method":
                    args = [OpcUaValue(option, DataTypes.String) if a == "option"
                            else _value(data, command.input_data_type, command.input_data_size)
                            for a in mapped.arguments]
                    outputs = await self.driver.call(nodes.object, nodes.node, args)
                    if command.gives_output:
                        if not outputs:
                            raise DeviceError(f"method {mapped.node} gave no output "
                                              f"argument (the map's {command.name} has one)")
                        self.host.data_feedback.post(outputs[0])
                case "write":
                    await self.driver.write(
                        nodes.node,
                        _value(data, command.input_data_type, command.input_data_size))
                case "read":
                    self.host.data_feedback.post(await self.driver.read(nodes.node))
                case "subscribe":
                    await self._stop_stream()
                    self._subscription = await self.driver.subscribe(
                        nodes.node, mapped.interval_ms, self._on_value)
                case "":  # StopData: end the stream
                    await self._stop_stream()
        except OpcUaStatusError as exc:
            raise DeviceError(f"the server answered {exc.status}: {exc}") from None
        except _LINK_ERRORS as exc:
            raise DeviceError(f"connection to {self.endpoint}: {_why(exc)}") from None
        return command.success_code

    def _on_value(self, value: Any) -> None:
        """A value of the running stream: one DataFeedback."""
        if self._subscription is not None:
            self.host.data_feedback.post(value)

    async def _stop_stream(self) -> None:
        subscription, self._subscription = self._subscription, None
        if subscription is not None and not self._lost:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(subscription.delete(), 5.0)


def _value(data: Any, data_type: DataTypes | None, size: tuple[int, ...]) -> OpcUaValue:
    """Checked input data (numpy) as the value an OPC UA method or variable takes: a
    scalar for size ``(1,)``, else an array (its shape kept if it has more than one axis)."""
    assert data_type is not None
    arr = np.asarray(data)
    if size == (1,):
        value = arr.reshape(-1)[0]
        return OpcUaValue(value if data_type is DataTypes.String else value.item(), data_type)
    dims = tuple(arr.shape) if arr.ndim > 1 else None
    return OpcUaValue(arr.reshape(-1).tolist(), data_type, is_array=True, dims=dims)


def _why(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__
